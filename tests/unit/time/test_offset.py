"""The carrier's clock offset from round trips, and a sample's age (mission.time.offset)."""
from __future__ import annotations

import pytest

from mission.time.offset import SHARED_CLOCK, OffsetEstimate, OffsetEstimator, RoundTrip, sample_age

OFFSET_S = 1000.0  # the carrier's clock runs this far ahead of ours [s]


def trip(sent_s: float, out_s: float, back_s: float) -> RoundTrip:
    """A ping sent at ``sent_s`` (our clock) that takes ``out_s`` to the carrier and ``back_s`` back."""
    return RoundTrip(sent_s, sent_s + out_s + OFFSET_S, sent_s + out_s + back_s)


def test_the_offset_lies_within_half_the_round_trip_whatever_the_paths_do():
    est = OffsetEstimator()
    assert est.estimate(0.0) is None
    assert est.add(trip(1.0, 0.010, 0.030)) is None  # asymmetric: the midpoint errs by 0.01, within 0.02
    got = est.estimate(1.04)
    assert got is not None and got.bound_s == pytest.approx(0.02, abs=1e-6)
    assert abs(got.offset_s - OFFSET_S) <= got.bound_s
    assert got.offset_s == pytest.approx(OFFSET_S - 0.01, abs=1e-9)


def test_the_tightest_recent_round_trip_wins_and_old_ones_age_out():
    est = OffsetEstimator(window_s=10.0, drift=1e-3)
    est.add(trip(1.0, 0.2, 0.2))
    est.add(trip(2.0, 0.005, 0.005))
    est.add(trip(3.0, 0.1, 0.1))
    got = est.estimate(4.0)
    assert got is not None and got.offset_s == pytest.approx(OFFSET_S) and got.bound_s == pytest.approx(0.005 + 1e-3 * 1.99)
    assert est.estimate(30.0) is None  # all out of the window


def test_a_relay_that_delays_the_pings_too_widens_the_bound_and_hides_nothing():
    """Delaying the round trip as the states by 0.45 s each way: the offset's bound is 0.45 s, so
    a state 0.45 s late may be up to 0.9 s old: beyond any approach budget."""
    est = OffsetEstimator()
    est.add(trip(1.0, 0.45, 0.45))
    got = est.estimate(2.0)
    assert got is not None and got.bound_s >= 0.45
    stamp = 5.0 + OFFSET_S  # measured at 5.0 of ours, arrives 0.45 s late
    age = sample_age(5.45, stamp, got)
    assert age - got.bound_s <= 0.45 <= age + got.bound_s


def test_round_trips_that_cannot_be_are_refused_with_a_reason():
    est = OffsetEstimator(max_round_trip_s=1.0)
    assert est.add(RoundTrip(2.0, OFFSET_S, 1.0)) == "rtt"  # answered before it was asked
    assert est.add(trip(1.0, 0.8, 0.8)) == "rtt"  # too long to bound anything
    assert est.add(trip(1.0, 0.01, 0.01)) is None
    assert est.add(RoundTrip(3.0, 3.0 + OFFSET_S + 0.5, 3.02)) == "inconsistent"  # the carrier's clock jumped 0.5 s
    assert est.refused == {"rtt": 2, "inconsistent": 1}


def test_a_carrier_clock_that_moved_for_good_is_taken_after_a_few_round_trips():
    """A restarted carrier counts from another origin: the first round trips that disagree are
    refused (a forged answer would look the same), ``restart_after`` in a row start it over."""
    est = OffsetEstimator(restart_after=4)
    est.add(trip(1.0, 0.01, 0.01))
    moved = [RoundTrip(2.0 + i, 2.0 + i + 0.01 + 50.0, 2.02 + i) for i in range(4)]  # its clock now 50 s ahead
    assert [est.add(t) for t in moved] == ["inconsistent", "inconsistent", "inconsistent", None]
    got = est.estimate(6.0)
    assert got is not None and got.offset_s == pytest.approx(50.0) and est.refused["restarted"] == 1


def test_age_is_since_the_carrier_measured_the_sample():
    assert sample_age(10.0, 9.55 + OFFSET_S, OffsetEstimate(OFFSET_S, 0.0)) == pytest.approx(0.45)
    assert sample_age(10.0, 9.98, SHARED_CLOCK) == pytest.approx(0.02)  # lockstep: one clock


def test_a_delay_that_grows_is_a_fault_with_a_reason_once_per_episode():
    from mission.time.offset import DelayWatch

    watch = DelayWatch(window_s=10.0, growth_s=0.1)
    assert all(watch.add(0.1 * i, 0.02) is None for i in range(20))  # a steady 20 ms
    why = watch.add(2.0, 0.47)  # a relay starts holding the states 0.45 s
    assert why == "carrier states arrive 0.47 s after the carrier measured them, 0.45 s later than within the last 10 s"
    assert watch.add(2.1, 0.47) is None and watch.growths == 1  # the same episode
    assert watch.add(2.2, 0.03) is None  # back to normal ...
    assert watch.add(2.3, 0.5) is not None and watch.growths == 2  # ... and a second episode



def _searched_watch(window_s: float, growth_s: float):
    """DelayWatch.add as a search of the whole window each time (the reference)."""
    recent: list[tuple[float, float]] = []
    growing = [False]

    def add(rx_s: float, transit_s: float) -> str | None:
        recent[:] = [(t, d) for t, d in recent if rx_s - t <= window_s] + [(rx_s, transit_s)]
        least = min(d for _, d in recent)
        if transit_s - least > growth_s:
            if growing[0]:
                return None
            growing[0] = True
            return f"{transit_s:.2f} {transit_s - least:.2f}"
        if transit_s - least <= growth_s / 2:
            growing[0] = False
        return None
    return add


def test_the_delay_watch_finds_the_least_of_its_window_as_a_search_of_it_would():
    """The sliding-window minimum gives what searching the whole window gives: states in order,
    equal times and transits, and after a clock that stepped back."""
    import random

    from mission.time.offset import DelayWatch

    rng = random.Random(3)
    for back in (False, True):
        watch, searched, rx = DelayWatch(window_s=1.0, growth_s=0.05), _searched_watch(1.0, 0.05), 0.0
        for i in range(3000):
            rx += -0.7 if back and i in (1000, 2000) else rng.choice([0.0, 0.02, 0.05, 0.3])
            transit = rng.choice([0.01, 0.02, 0.03, 0.2, rng.random()])
            got, want = watch.add(rx, transit), searched(rx, transit)
            assert (got is None) == (want is None), i
            if got is not None:
                assert got.startswith(f"carrier states arrive {want.split()[0]} s") and f", {want.split()[1]} s later" in got
