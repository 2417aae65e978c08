"""The carrier trusts only its own passenger (real Zenoh, the carrier on a manual clock):
fake RIDING statuses before any passenger exists, a flood of SEPARATED and ABORT from another
session while the real passenger rides, and, with the pair's key, the same unsigned and with
the passenger's own source id copied. The carrier ignores them all."""
from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import zenoh

from mission.bus.auth import BusAuth
from mission.bus.bridge import keys
from mission.bus.wire import PassengerStatus
from mission.config.keys import read_private_key_file, read_public_key_file, write_key_pair
from mission.config.schema import Config, from_dict
from mission.time.clock import ManualClock
from sim.robots.carrier import CarrierMode, CarrierSim
from tests.integration.carrier.test_carrier_sim import TARGET, Passenger, _seen, sessions
from tests.support.zenoh_util import wait_for

pytestmark = pytest.mark.timeout(60)

DT = 1.0 / 30.0
KEY = keys("trust").passenger_state
BLOCK = zenoh.CongestionControl.BLOCK


def _cfg(key_file: Path | None = None) -> Config:
    zenoh_section: dict[str, object] = {"pair": "trust"}
    if key_file is not None:
        zenoh_section["signing_key_file"] = str(key_file)
    return from_dict({"zenoh": zenoh_section, "scenario": {"carrier_start": [0.0, 0.0, 0.0], "target": TARGET.tolist()},
                      "safety": {"carrier_max_accel_m_s2": 1.0}, "carrier": {"rate_hz": 30.0, "max_speed_m_s": 2.0}})


def _fake(phase: str, seq: int, at: list[float] | np.ndarray = (0.0, 0.0, -1.5)) -> bytes:
    return PassengerStatus(phase, 0.0, seq, at, [0, 0, 0], phase == "SEPARATED").to_json()


def _steps(sim: CarrierSim, clock: ManualClock, n: int) -> float:
    """Step the carrier ``n`` times; its distance to the target after [m]."""
    for _ in range(n):
        clock.advance(DT)
        sim.step(DT)
    return float(np.linalg.norm(TARGET[:2] - sim.position_m[:2]))


def _heard(sim: CarrierSim, reason: str, put: Callable[[int], None], timeout_s: float = 10.0) -> int:
    """Put (``put(k)``, k = 0, 1, ...) until the carrier's passenger feed has dropped one for
    ``reason``: the rogue's session has then learnt of the feed's subscription (a put before that
    reaches nobody, and a fresh session learns it when it will). Returns that drop count."""
    deadline, k = time.monotonic() + timeout_s, 0
    while not sim.passenger.counters["dropped"].get(reason, 0):
        assert time.monotonic() < deadline, f"no put of the rogue reached the carrier's feed ({reason})"
        put(k)
        k += 1
        time.sleep(0.05)
    return int(sim.passenger.counters["dropped"][reason])


def test_fake_riding_before_any_passenger_and_a_flood_while_it_rides_are_ignored() -> None:
    clock = ManualClock()
    with sessions(2) as (sa, rogue, sb), CarrierSim(_cfg(), clock, sa) as sim:
        start = _steps(sim, clock, 1)
        # on main a RIDING from anyone, before any passenger existed, sent the carrier off alone;
        # these claim to ride right on the dock point, from the first status on
        heard = _heard(sim, "unbound", lambda k: rogue.put(KEY, _fake("RIDING", 10**6 + k), congestion_control=BLOCK))
        for k in range(30):
            rogue.put(KEY, _fake("RIDING", 10**6 + 1000 + k), congestion_control=BLOCK)
        wait_for(lambda: sim.passenger.counters["dropped"].get("unbound", 0) >= heard + 30, what="30 more unbound")
        assert _steps(sim, clock, 60) == start and sim.mode is CarrierMode.WAITING  # it never moved
        passenger = Passenger(sb, "trust", clock, sim)
        try:
            wait_for(lambda: passenger.pub.matched)
            seq = passenger.say("RIDING")  # stood on the deck first: bound, then rides
            wait_for(lambda: _seen(sim, seq), what="the real RIDING")
            before = _steps(sim, clock, 30)
            assert sim.mode is CarrierMode.APPROACHING and before < start
            # on main a flood of SEPARATED/ABORT stopped the carrier at 20-22 m and made 8309 real
            # statuses stale: from another session now it is a foreign source, dropped and counted
            for k in range(300):
                rogue.put(KEY, _fake(("SEPARATED", "ABORT")[k % 2], 10**7 + k), congestion_control=BLOCK)
                if k % 30 == 29:
                    seq = passenger.say("RIDING")
                    wait_for(lambda: _seen(sim, seq), what="the real RIDING among the flood")
                    _steps(sim, clock, 10)
            wait_for(lambda: sim.passenger.counters["dropped"].get("source", 0) == 300, what="the flood dropped")
            assert sim.mode is CarrierMode.APPROACHING and _steps(sim, clock, 5) < before
            c = sim.passenger.counters
            assert set(c["dropped"]) == {"unbound", "source"} and c["rejected_sources"] == {"anonymous": 300}, c
        finally:
            passenger.pub.close()


def test_with_the_key_unsigned_statuses_with_the_passenger_s_own_source_id_are_dropped(tmp_path: Path) -> None:
    """A copier of the passenger's Zenoh source id (higher sequence numbers, SEPARATED or ABORT):
    without a key it would pass as the passenger; with one, unsigned, it is dropped before the
    feed looks at it, and the carrier approaches on."""
    key_file = tmp_path / "bus.key"
    key_file.write_text("a5" * 32)
    cfg = _cfg(key_file)
    clock = ManualClock()
    with sessions(2) as (sa, rogue, sb), CarrierSim(cfg, clock, sa) as sim:
        passenger = Passenger(sb, "trust", clock, sim, auth=sim.auth)  # the real one signs
        try:
            wait_for(lambda: passenger.pub.matched)
            seq = passenger.say("RIDING")
            wait_for(lambda: _seen(sim, seq), what="the signed RIDING")
            before = _steps(sim, clock, 30)
            source = zenoh.SourceInfo(passenger.pub._state.id, 10**6)  # copied, as anyone on the network sees it
            def copy(k: int) -> None:
                rogue.put(KEY, _fake(("SEPARATED", "ABORT")[k % 2], 10**7 + k), source_info=source, congestion_control=BLOCK)

            heard = _heard(sim, "unsigned", copy)
            for k in range(100):
                copy(1000 + k)
            wait_for(lambda: sim.passenger.counters["dropped"].get("unsigned", 0) >= heard + 100, what="100 more unsigned")
            seq = passenger.say("RIDING")
            wait_for(lambda: _seen(sim, seq), what="the signed RIDING after the copies")
            assert _steps(sim, clock, 10) < before and sim.mode is CarrierMode.APPROACHING
            assert sim.passenger.counters["bound_source"].startswith("signer:")
        finally:
            passenger.pub.close()


def test_unsigned_a_rogue_that_stood_on_the_deck_first_is_contested_by_the_real_passenger() -> None:
    """On an unsigned bus a rogue that says PREFLIGHT before the mission starts, then RIDING on the
    dock point, binds: unsigned, nothing tells it from the real passenger (the start-up WARNING says
    so). When the real passenger then stands on the deck too (its PREFLIGHT statuses), the binding
    is contested: the carrier stops and trusts neither, whatever either says next. On main the real
    statuses were dropped as a foreign source and the carrier drove on with the rogue, empty."""
    clock = ManualClock()
    with sessions(2) as (sa, rogue_session, sb), CarrierSim(_cfg(), clock, sa) as sim:
        start = _steps(sim, clock, 1)
        rogue = Passenger(rogue_session, "trust", clock, sim)
        real = Passenger(sb, "trust", clock, sim)
        try:
            wait_for(lambda: rogue.pub.matched and real.pub.matched)
            seq = rogue.say("RIDING")
            wait_for(lambda: _seen(sim, seq), what="the rogue's RIDING")
            moved = _steps(sim, clock, 30)
            assert sim.mode is CarrierMode.APPROACHING and moved < start  # unsigned: the rogue won the binding
            for _ in range(3):
                real._send("PREFLIGHT")
            wait_for(lambda: sim.passenger.counters["contest"] is not None, what="the contest")
            stopped = _steps(sim, clock, 45)  # beyond carrier.passenger_timeout_s: both silent to it
            for who in (rogue, real, rogue):
                who.say("RIDING")
            wait_for(lambda: sim.passenger.counters["dropped"].get("contest", 0) >= 3, what="both refused")
            assert _steps(sim, clock, 30) == pytest.approx(stopped, abs=1e-9) and sim.mode is not CarrierMode.APPROACHING
            assert "a second passenger" in sim.passenger.counters["contest"]
        finally:
            rogue.pub.close()
            real.pub.close()


def test_with_one_key_per_robot_a_rogue_never_binds_and_the_real_passenger_does(tmp_path: Path) -> None:
    """The carrier verifies statuses with the passenger's public key only: a rogue that stands on
    the deck first and rides on the dock point, unsigned or signed with a key of its own, never
    binds (``unsigned``, ``signature``); the carrier never moves until the real passenger, signing
    with its own key, stands on the deck and rides."""
    for robot in ("carrier", "passenger", "rogue"):
        write_key_pair(tmp_path / f"{robot}.key", tmp_path / f"{robot}.pub")
    cfg = from_dict({**_cfg().model_dump(exclude_unset=True),
                     "zenoh": {"pair": "trust", "private_key_file": str(tmp_path / "carrier.key"),
                               "peer_public_key_file": str(tmp_path / "passenger.pub")}})
    carrier_pub = read_public_key_file(tmp_path / "carrier.pub", "carrier")
    clock = ManualClock()
    with sessions(3) as (sa, unsigned_session, keyed_session, sb), CarrierSim(cfg, clock, sa) as sim:
        start = _steps(sim, clock, 1)
        rogues = [Passenger(unsigned_session, "trust", clock, sim),
                  Passenger(keyed_session, "trust", clock, sim,
                            auth=BusAuth.per_robot(read_private_key_file(tmp_path / "rogue.key", "rogue"), carrier_pub))]
        real = Passenger(sb, "trust", clock, sim,
                         auth=BusAuth.per_robot(read_private_key_file(tmp_path / "passenger.key", "passenger"), carrier_pub))
        try:
            wait_for(lambda: all(p.pub.matched for p in (*rogues, real)))
            for rogue in rogues:
                rogue.say("RIDING")
            wait_for(lambda: sim.passenger.counters["dropped"].get("unsigned", 0) >= 4
                     and sim.passenger.counters["dropped"].get("signature", 0) >= 4, what="the rogues refused")
            assert _steps(sim, clock, 30) == start and sim.mode is CarrierMode.WAITING
            assert sim.passenger.counters["bound_source"] is None
            seq = real.say("RIDING")
            wait_for(lambda: _seen(sim, seq), what="the real RIDING")
            assert _steps(sim, clock, 20) < start and sim.mode is CarrierMode.APPROACHING
            c = sim.passenger.counters
            assert c["bound_source"].startswith("signer:") and c["contest"] is None, c
        finally:
            for p in (*rogues, real):
                p.pub.close()
