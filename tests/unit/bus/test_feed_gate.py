"""The carrier feed's source binding and plausibility gate (pure, no Zenoh): a second source,
an outlier, a stamp an hour ahead, a teleport, a relocalised carrier."""
from __future__ import annotations

import numpy as np
import pytest

from mission.bus.gate import FeedGate, GateLimits, Sample, implausible

LIMITS = GateLimits(max_speed_m_s=2.0)
RATE_HZ = 30.0


def track(n: int, *, start: int = 0, north0: float = 0.0, v: float = 1.0, seq0: int = 0, t0: float = 0.0) -> list[Sample]:
    """A carrier driving north at ``v`` m/s, sampled at 30 Hz (stamp = receive time)."""
    out = []
    for k in range(start, start + n):
        t = t0 + k / RATE_HZ
        out.append(Sample(seq0 + k, t, np.array([north0 + v * (t - t0), 0.0, 0.0]), np.array([v, 0.0, 0.0]), t))
    return out


def offer_all(gate: FeedGate, source: str, samples: list[Sample]) -> list[str | None]:
    return [gate.offer(source, s) for s in samples]


def test_binds_after_three_plausible_samples_and_drops_every_other_source() -> None:
    gate = FeedGate(LIMITS)
    real = track(60)
    assert offer_all(gate, "real", real[:3]) == ["unbound", "unbound", None]
    assert gate.bound == "real"
    # a rogue with higher sequence numbers, 50 m away, interleaved: every one dropped and counted
    rogue = [Sample(10_000 + k, s.stamp_s, s.position_ned_m + [50.0, 0, 0], s.velocity_ned_m_s, s.rx_s) for k, s in enumerate(real)]
    results = [(gate.offer("rogue", r), gate.offer("real", s)) for r, s in zip(rogue[3:], real[3:])]
    assert all(r == "source" and s is None for r, s in results)
    assert gate.rejected_sources == {"rogue": 57}


def test_a_single_stray_sample_does_not_bind_and_an_inconsistent_track_never_does() -> None:
    gate = FeedGate(LIMITS)
    stray = track(1, north0=50.0)[0]
    assert gate.offer("stray", stray) == "unbound"
    real = track(10, start=1)
    assert offer_all(gate, "real", real[:3])[-1] is None and gate.bound == "real"
    # samples that jump 20 m each never make 3 plausible in a row
    gate = FeedGate(LIMITS)
    jumpy = [Sample(k, k / RATE_HZ, np.array([20.0 * (k % 2), 0, 0]), np.zeros(3), k / RATE_HZ) for k in range(10)]
    assert set(offer_all(gate, "j", jumpy)) == {"unbound"} and gate.bound is None


@pytest.mark.parametrize("name, change, reason", [
    ("an hour ahead", {"stamp_s": 3600.0}, "stamp_jump"),
    ("20 m teleport", {"position_ned_m": np.array([20.0, 0.0, 0.0])}, "jump"),
    ("speed over the limit", {"velocity_ned_m_s": np.array([9.0, 0.0, 0.0])}, "speed"),
    ("velocity against the motion", {"velocity_ned_m_s": np.array([-2.5, 0.0, 0.0])}, "velocity"),
    ("sequence jump", {"seq": 10**9}, "seq_jump"),
    ("old sequence", {"seq": 0}, "stale_seq"),
    ("old stamp", {"stamp_s": 0.0}, "stale_stamp"),
])
def test_one_outlier_is_dropped_and_never_poisons_the_samples_after_it(name: str, change: dict, reason: str) -> None:
    gate = FeedGate(LIMITS)
    samples = track(40)
    assert offer_all(gate, "c", samples[:20])[-1] is None
    s = samples[20]
    bad = Sample(**{"seq": s.seq, "stamp_s": s.stamp_s, "position_ned_m": s.position_ned_m + [0.3, 0, 0],
                    "velocity_ned_m_s": s.velocity_ned_m_s, "rx_s": s.rx_s, **change})
    assert gate.offer("c", bad) == reason, name
    assert offer_all(gate, "c", samples[21:]) == [None] * 19  # the next honest sample is accepted at once
    assert gate.resyncs == 0


def test_one_percent_outliers_all_dropped_and_all_honest_samples_accepted() -> None:
    rng = np.random.default_rng(3)
    gate = FeedGate(LIMITS)
    samples = track(3000)
    bad = set(rng.choice(np.arange(10, 3000), size=30, replace=False).tolist())
    for k, s in enumerate(samples):
        if k in bad:
            kind = k % 3
            out = Sample(s.seq, s.stamp_s + (3600.0 if kind == 0 else 0.0),
                         s.position_ned_m + ([20.0, 0, 0] if kind == 1 else [0, 0, 0]),
                         s.velocity_ned_m_s * (10.0 if kind == 2 else 1.0), s.rx_s)
            assert gate.offer("c", out) is not None
        else:
            assert gate.offer("c", s) == (None if k >= 2 else "unbound")


def test_a_relocalised_carrier_is_followed_after_a_consistent_track_of_its_own() -> None:
    gate = FeedGate(LIMITS)
    before = track(10)
    offer_all(gate, "c", before)
    after = track(10, start=10, north0=30.0)  # the carrier's localisation jumped 30 m for good
    results = offer_all(gate, "c", after)
    assert results[:4] == ["jump"] * 4 and results[4:] == [None] * 6
    assert gate.resyncs == 1


def test_unbind_lets_a_restarted_carrier_bind_again() -> None:
    gate = FeedGate(LIMITS)
    offer_all(gate, "c1", track(5))
    gate.unbind()
    assert offer_all(gate, "c2", track(3, seq0=0, north0=-7.0)) == ["unbound", "unbound", None]
    assert gate.bound == "c2"


def test_foreign_sources_are_counted_by_name_up_to_a_bound() -> None:
    gate = FeedGate(LIMITS)
    real = track(3)
    offer_all(gate, "real", real)
    for i in range(40):
        gate.offer(f"rogue{i}", real[-1])
    assert len(gate.rejected_sources) == 17 and gate.rejected_sources["other"] == 24


def test_implausible_accepts_a_carrier_at_its_top_speed_after_a_silence() -> None:
    a = Sample(1, 0.0, np.zeros(3), np.array([2.0, 0, 0]), 0.0)
    b = Sample(31, 1.0, np.array([2.0, 0, 0]), np.array([2.0, 0, 0]), 1.2)  # 1 s later, 2 m on
    assert implausible(a, b, LIMITS, use_seq=True) is None
    with pytest.raises(ValueError):
        GateLimits(max_speed_m_s=0.0)


def test_after_a_silence_one_state_is_not_believed_a_track_of_five_is() -> None:
    """A spoofed state 20 m on right after a 4 s silence is within top speed x elapsed, so only a
    consistent track may follow a gap: the spoof and the honest states after it are held back
    until five agree, and the spoof never becomes the reference."""
    gate = FeedGate(LIMITS)
    offer_all(gate, "c", track(10))
    after = track(10, start=130)  # 4 s later, honest, 4 m on
    spoof = Sample(after[0].seq - 1, after[0].stamp_s - 0.01, after[0].position_ned_m + [20.0, 0, 0],
                   after[0].velocity_ned_m_s, after[0].rx_s - 0.01)
    assert gate.offer("c", spoof) == "gap"
    assert offer_all(gate, "c", after) == ["gap"] * 4 + [None] * 6
    assert gate.resyncs == 1 and gate.describe_reference().startswith(f"seq {after[-1].seq} ")
    # the honest track after the silence follows the old reference within the carrier's limits (4 m
    # in 4 s at 1 m/s): the same carrier moving on, trusted at once, not a jump
    assert gate.jumps == 0 and gate.distrust(after[-1].rx_s) is None


# ------------------------------------------------------------------------------------- trust


def test_a_new_reference_is_trusted_only_after_settle_s_within_the_carrier_s_limits() -> None:
    gate = FeedGate(LIMITS)  # settle_s 2 s
    samples = track(120)  # 4 s at 1 m/s
    offer_all(gate, "c", samples[:3])
    assert (gate.distrust(samples[2].rx_s) or "").startswith("settling") and "just bound" in gate.distrust(0.1)
    untrusted = [gate.offer("c", s) is None and gate.distrust(s.rx_s) is not None for s in samples[3:]]
    first_trusted = untrusted.index(False) + 3
    assert samples[first_trusted].rx_s - samples[0].rx_s == pytest.approx(2.0, abs=1 / RATE_HZ)
    assert not any(untrusted[first_trusted - 3:])  # trusted for good from then on


def test_after_a_relocalisation_the_new_track_is_not_trusted_for_settle_s() -> None:
    gate = FeedGate(LIMITS)
    offer_all(gate, "c", track(90))
    assert gate.distrust(3.0) is None
    after = track(120, start=90, north0=20.0)  # the carrier's localisation jumped 20 m for good
    results = offer_all(gate, "c", after)
    assert results[:4] == ["jump"] * 4 and gate.resyncs == 1 and gate.jumps == 1
    gate = FeedGate(LIMITS)  # again, asking after each state
    offer_all(gate, "c", track(90))
    trusted = [(gate.offer("c", s), gate.distrust(s.rx_s)) for s in after]
    assert all(d is None for _, d in trusted[:4])  # the jumps were dropped: the old reference stands
    assert all("after a resync" in (d or "") for _, d in trusted[4:60])
    assert all(d is None for _, d in trusted[61:])  # 2 s from the resync track's first state


def test_a_burst_of_five_spoofed_states_never_leaves_a_trusted_reference_behind() -> None:
    """The attack that fired the latch with the real carrier 25 m out: 5 spoofed states from the
    carrier's own source id, 7 m short of the target, ahead in sequence. The gate follows them
    (5 in a row are a track), then the honest states take the reference back; no state is
    trusted until the honest track has settled, and the spoofed ones never are."""
    gate = FeedGate(LIMITS)
    honest = track(240)
    offer_all(gate, "c", honest[:90])
    t = honest[90].rx_s
    burst = [Sample(honest[90].seq + 1 + k, t + 0.001 * k, np.array([60.0, 0.0, 0.0]), np.zeros(3), t + 0.001 * k)
             for k in range(5)]
    offer_all(gate, "c", burst)
    assert gate.resyncs == 1 and gate.distrust(t + 0.01) is not None  # on the spoof, but not trusted
    trust = [(gate.offer("c", s), gate.distrust(s.rx_s)) for s in honest[91:]]
    back = next(i for i, (r, _) in enumerate(trust) if r is None)
    assert gate.resyncs == 2 and gate.jumps == 2 and all(d is not None for _, d in trust[:back + 55])
    assert trust[-1][1] is None  # the honest track, settled


def test_a_copier_of_the_source_id_with_a_higher_sequence_makes_the_source_contested() -> None:
    """Without a signing key a publisher can copy the carrier's source id and send seq + 1: the
    honest states are then stale. Three in a second mark the source contested (untrusted) until
    settle_s after the last one."""
    gate = FeedGate(LIMITS)
    honest = track(150)
    offer_all(gate, "c", honest[:90])
    assert gate.distrust(honest[89].rx_s) is None
    for s in honest[90:120]:  # the copier's state just ahead of each honest one
        copy = Sample(s.seq + 1, s.stamp_s, s.position_ned_m + [0.05, 0, 0], s.velocity_ned_m_s, s.rx_s)
        assert gate.offer("c", copy) is None
        assert gate.offer("c", s) == "stale_seq"
    assert gate.contests == 1 and (gate.distrust(honest[119].rx_s) or "").startswith("contested")
    results = offer_all(gate, "c", honest[120:])  # the copier stops
    assert gate.distrust(honest[119].rx_s + 1.9) is not None and gate.distrust(honest[119].rx_s + 2.1) is None, results


def test_sporadic_stale_states_and_outliers_never_contest_the_source() -> None:
    gate = FeedGate(LIMITS)
    samples = track(900)
    offer_all(gate, "c", samples[:90])
    for k, s in enumerate(samples[90:], start=90):
        if k % 40 == 0:  # 2.5 %: an old state again, and a teleport
            assert gate.offer("c", samples[k - 5]) == "stale_seq"
            assert gate.offer("c", Sample(s.seq, s.stamp_s, s.position_ned_m + [20.0, 0, 0], s.velocity_ned_m_s, s.rx_s)) == "jump"
        assert gate.offer("c", s) is None
        assert gate.distrust(s.rx_s) is None
    assert gate.contests == 0 and gate.resyncs == 0


def test_while_settling_a_state_beyond_the_carrier_s_own_limits_starts_the_settle_again() -> None:
    gate = FeedGate(LIMITS)  # max speed 2 m/s: the lax checks take up to 1.5 x 2 + 0.5 m/s
    fast = track(150, v=3.2)  # plausible for the lax gate, beyond the carrier's own speed
    results = offer_all(gate, "c", fast)
    assert results[2:] == [None] * 148 and all(gate.distrust(s.rx_s) for s in fast)
    assert gate.settles > 100  # every state restarted it
