"""Insiders and rogues on the bus (the three real processes, the Zenoh router in the test).

An insider with a key signs carrier states under the real carrier's signer id with a counter 50 s
ahead of the real stream, walking the claimed carrier towards the target at 1 m/s (lockstep):

- With the pair's shared key (``--zenoh-signing-key``) it can sign: on main the real states were
  then dropped as ``replay``, silently, and the latch fired with the real carrier 12.98 m out.
  Now a counter far ahead of its own stream is a contest: the signer is refused for good, the
  real stream with it (``contest``), the feed says why, and the mission never separates on it.
- With one key per robot (``--zenoh-private-key``, ``--zenoh-peer-key``) an insider holding the
  passenger's own key cannot sign as the carrier at all: every forgery is dropped as
  ``signature``, the feed never doubts its carrier, and P1-P3 hold.

A rogue passenger says PREFLIGHT before the mission starts, then RIDING on the dock point: it
takes an unsigned bus (said at start-up), and never binds with one key per robot.
"""
from __future__ import annotations

import json
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zenoh

from mission.bus.wire import PassengerStatus
from mission.bus.signing import ED25519_TRAILER_BYTES, TRAILER_BYTES, Ed25519Signer, Signer, pair_key
from mission.config.keys import read_private_key_file, write_key_pair
from tests.adversarial.test_bus_attacks import (AT_SEPARATION_M, BC, GUARD_M, KEY, PAIR_KEYS, SPEED, TOWARDS, Attacker,
                                                Put, spoof)
from tests.faults.procs import assert_safe_end, flight
from tests.faults.test_matrix import assert_never_disarmed_in_the_air, concurrently
from tests.support.zenoh_util import wait_for

pytestmark = [pytest.mark.slow, pytest.mark.timeout(240)]
# A class per test: `--dist loadscope` schedules a class as its own unit, so the flights spread over the workers.

AHEAD_US = 50_000_000  # the insider's counter: 50 s ahead of the real carrier's
# Once the signer is refused for good, every real carrier state is refused too: the mission's lockstep
# relay never sees the sample each carrier step names and gives it up after `run --lockstep-lost-wall`
# (2 s of wall by default: ~45 steps, 90 s, between the contest and the mission's end). 0.3 s flies the
# same simulated flight (the relay goes on without the sample either way), ~80 s sooner.
LOST_WALL = ("--lockstep-lost-wall", "0.3")


class Insider:
    """Once the real carrier has moved 2 m: for every real state, a forged one under the real
    signer id (read from its tag), counter 50 s ahead, the claimed carrier walking towards the
    target at 1 m/s, signed with ``make_signer(signer_id)``."""

    def __init__(self, make_signer: Any, trailer_bytes: int) -> None:
        self.make_signer, self.trailer_bytes = make_signer, trailer_bytes
        self.signer: Signer | None = None
        self.walk_from: float | None = None
        self.forged = 0

    def __call__(self, st: dict[str, Any], source: Any, attachment: bytes | None, raw: bytes) -> list[Put]:
        stamp, seq, pos, vel = st["stamp"], st["seq"], np.array(st["position"]), np.array(st["velocity"])
        if attachment is None or len(attachment) < self.trailer_bytes:
            return []
        if self.walk_from is None and np.linalg.norm(pos) > 2.0:
            self.walk_from = stamp
            self.signer = self.make_signer(attachment[-self.trailer_bytes:][4:12])
        if self.walk_from is None or self.signer is None:
            return []
        payload = spoof(seq + 1, stamp + 0.001, pos + TOWARDS * (stamp - self.walk_from), vel + TOWARDS)
        now_us = time.time_ns() // 1000 + AHEAD_US
        self.forged += 1
        return [Put(PAIR_KEYS.carrier_state, payload, True,
                    self.signer.attachment(PAIR_KEYS.carrier_state, payload, now_us))]


def _shared_key_insider(tmp_path: Path) -> None:
    key = tmp_path / "bus.key"
    key.write_text(KEY.hex())
    signed = ("--zenoh-signing-key", str(key))
    insider = Insider(lambda sid: Signer(pair_key(KEY, "pair0"), signer=sid), TRAILER_BYTES)
    with flight(tmp_path, "shared-insider", speed=SPEED, lockstep=True, carrier_args=signed,
                mission_args=(*signed, *LOST_WALL)) as f:
        f.wait_phase("RIDING")
        attacker = Attacker(insider, session=f.router.session)
        try:
            code = f.wait_mission(120.0)
        finally:
            attacker.close()
        s = f.summary()
        assert "Traceback" not in f.text("mission.err") + f.text("carrier.err")
        assert_never_disarmed_in_the_air(f)
        assert_safe_end(f, modes=("AUTO.LOITER", "landed"))
    carrier = f.carrier_summary()
    assert insider.forged >= 1, vars(insider)
    feed = s["carrier_feed"]
    # the forgery ahead of the stream is a contest, and the real stream is refused with it (not "replay")
    assert feed["dropped"].get("contest", 0) >= 2 and "ahead of its own stream" in (feed["contest"] or ""), feed
    assert feed["dropped"].get("replay", 0) == 0, feed
    # no separation on the walked track: none at all (the mission stops on a carrier it cannot trust)
    assert code != 0 and s["separation_time_s"] is None, (code, s.get("separation_time_s"))
    assert "not trusted: signer contest: counter 50" in f.text("mission.out") + f.text("mission.err")
    assert carrier["closest_target_distance_m"] >= GUARD_M - 0.05, carrier


def _per_robot_insider(tmp_path: Path) -> None:
    folder = tmp_path / "keys"
    folder.mkdir()
    for robot in ("carrier", "passenger"):
        write_key_pair(folder / f"{robot}.key", folder / f"{robot}.pub")
    passenger_key = read_private_key_file(folder / "passenger.key", "passenger")
    insider = Insider(lambda sid: Ed25519Signer(passenger_key, signer=sid), ED25519_TRAILER_BYTES)
    carrier_args = ("--zenoh-private-key", str(folder / "carrier.key"), "--zenoh-peer-key", str(folder / "passenger.pub"))
    mission_args = ("--zenoh-private-key", str(folder / "passenger.key"), "--zenoh-peer-key", str(folder / "carrier.pub"))
    with flight(tmp_path, "robot-insider", speed=SPEED, lockstep=True, carrier_args=carrier_args,
                mission_args=mission_args) as f:
        f.wait_phase("RIDING")
        attacker = Attacker(insider, session=f.router.session)
        try:
            f.wait_phase("NAVIGATING", 90.0)
            sent = attacker.stop()
            code = f.wait_mission(60.0)
        finally:
            attacker.close()
        assert code == 0, f.text("mission.err")[-3000:]
        s = f.summary()
        assert_safe_end(f, modes=("AUTO.LOITER",))
    carrier = f.carrier_summary()
    feed = s["carrier_feed"]
    assert insider.forged >= 30 and feed["dropped"].get("signature", 0) == sent[f"{PAIR_KEYS.carrier_state} replay"], (sent, feed)
    assert feed["contests"] == 0 and feed["resyncs"] == 0 and feed["contest"] is None, feed
    assert s["p1"] and s["p2"] and s["p3"] and s["carrier_target_distance_at_separation_m"] == pytest.approx(BC, abs=0.05)
    assert AT_SEPARATION_M - 0.2 <= carrier["distance_at_separation_m"] <= AT_SEPARATION_M + 0.05, carrier


class TestAnInsider:
    def test_an_insider_signing_ahead_of_the_carrier_is_a_contest_or_cannot_sign_at_all(self, tmp_path: Path) -> None:
        concurrently(lambda: _shared_key_insider(tmp_path), lambda: _per_robot_insider(tmp_path))


class RoguePassenger:
    """A passenger of its own on the pair's bus from before the mission starts: PREFLIGHT
    statuses (it "stands on the deck") until five of them went out after the carrier was heard, then RIDING on the carrier's dock point (1.5 m above the
    newest carrier state it heard), 20 per wall second, unsigned; the carrier's positions recorded."""

    def __init__(self, session: Any) -> None:
        self.session, self.sent, self.standing, self.positions = session, 0, 0, []
        self._stop = threading.Event()
        self._sub = session.declare_subscriber(PAIR_KEYS.carrier_state, self._on_state)
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _on_state(self, sample: Any) -> None:
        try:
            self.positions.append(json.loads(sample.payload.to_bytes())["position"])
        except (ValueError, KeyError):
            pass

    def _run(self) -> None:
        while not self._stop.wait(0.05):
            at = np.add(self.positions[-1] if self.positions else [0.0, 0.0, 0.0], [0.0, 0.0, -1.5])
            heard = bool(self.positions)  # the carrier is up (before: nobody hears the rogue)
            phase = "RIDING" if self.standing >= 5 else "PREFLIGHT"
            self.standing += heard and phase == "PREFLIGHT"
            self.sent += 1
            try:
                self.session.put(PAIR_KEYS.passenger_state,
                                 PassengerStatus(phase, 0.01 * self.sent, 10**6 + self.sent, at, [0, 0, 0], False).to_json())
            except zenoh.ZError:
                return

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5.0)
        self._sub.undeclare()


class TestARoguePassenger:
    def test_a_rogue_passenger_before_the_mission_takes_an_unsigned_bus_and_never_binds_signed(self, tmp_path: Path) -> None:
        """The PREFLIGHT-then-RIDING rogue, speaking before the mission starts (real processes; real
        time unsigned, lockstep signed). Unsigned it wins the binding: nothing tells it from the
        passenger, and the start-up WARNING says so (the carrier-level contest, once the real
        passenger stands on the deck too, is in tests/integration/carrier/test_carrier_trust.py). With
        one key per robot it never binds: the real passenger does, and the mission flies P1-P3. On
        main, unsigned, the carrier drove off empty to 9.9 m from the target and the real mission
        refused to start."""
        concurrently(lambda: _rogue_unsigned(tmp_path), lambda: _rogue_signed(tmp_path))


def _start_without_carrier(f: Any) -> None:
    """The mission and the vehicle of flight ``f`` whose carrier already runs."""
    start_carrier = f.start_carrier
    f.start_carrier = lambda *a, **k: None
    try:
        f.start()
    finally:
        f.start_carrier = start_carrier


def _rogue_unsigned(tmp_path: Path) -> None:
    """What an unsigned bus cannot prevent, and what it still does: the rogue binds and the carrier
    drives off empty before the mission is up (both processes said at start-up that the bus can be
    taken); the P3 guard still holds the carrier, and the real mission, its carrier gone from under
    the vehicle, refuses to fly (Assumption 2) and never arms."""
    with flight(tmp_path, "rogue-unsigned", speed=SPEED, start=False) as f:
        rogue = RoguePassenger(f.router.session)
        try:
            f.start_carrier()
            wait_for(lambda: rogue.standing >= 5 and "passenger feed bound" in f.text("carrier.err"), 30.0,
                     "the rogue bound")
            _start_without_carrier(f)
            code = f.wait_mission(60.0)
        finally:
            rogue.close()
        s = f.summary()
        assert code != 0 and (s["phase"], s["reason"]) == ("ABORT", "geometry") and not f.vehicle()["armed"], s
        for name in ("carrier.err", "mission.err"):
            assert "WARNING: the bus of pair pair0 is unsigned" in f.text(name), name
    carrier = f.carrier_summary()
    assert carrier["closest_target_distance_m"] >= GUARD_M - 0.05, carrier


def _rogue_signed(tmp_path: Path) -> None:
    folder = tmp_path / "rogue-keys"
    folder.mkdir()
    for robot in ("carrier", "passenger"):
        write_key_pair(folder / f"{robot}.key", folder / f"{robot}.pub")
    carrier_args = ("--zenoh-private-key", str(folder / "carrier.key"), "--zenoh-peer-key", str(folder / "passenger.pub"))
    mission_args = ("--zenoh-private-key", str(folder / "passenger.key"), "--zenoh-peer-key", str(folder / "carrier.pub"))
    with flight(tmp_path, "rogue-signed", speed=SPEED, lockstep=True, start=False, carrier_args=carrier_args,
                mission_args=mission_args) as f:
        rogue = RoguePassenger(f.router.session)
        try:
            f.start_carrier()
            wait_for(lambda: rogue.sent >= 10, 30.0, "the rogue's RIDING")
            _start_without_carrier(f)
            code = f.wait_mission(150.0)
        finally:
            rogue.close()
        assert code == 0, f.text("mission.err")[-3000:]
        s = f.summary()
        assert "WARNING" not in f.text("carrier.err").replace("WARNING mission", "")
        assert f.text("carrier.err").count("passenger feed bound to source signer:") == 1  # the real one, once
    carrier = f.carrier_summary()
    pfeed = carrier["passenger_feed"]
    assert pfeed["dropped"].get("unsigned", 0) >= 10 and pfeed["contest"] is None, pfeed
    assert s["p1"] and s["p2"] and s["p3"], s
