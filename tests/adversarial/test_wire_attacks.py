"""Adversaries on both wires, over the real processes: the fault matrix's harness
(tests/faults/procs.py: carrier, ``marsupial run`` and the mock PX4 as subprocesses, a Zenoh
router in this process, a GCS observer on the vehicle's second link) with an attacker added.

Zenoh: a rogue publisher on the pair's carrier key with higher sequence numbers (50 m away, and
7 m short of the target, where a believed state would fire the separation latch at once); states
spoofed with the real carrier's own source id (one stamped an hour ahead, one 20 m teleport
towards the target, then sporadic outliers); 10 MB payloads. MAVLink: a rogue sysid 42 PX4
HEARTBEAT before the vehicle appears; a rogue that talks alone until it is adopted
(``mavlink.target_system`` unset), then the real vehicle; unsigned spoofed HEARTBEATs (POSCTL,
and copies of the real state) with signing on; a vehicle signing with another key.

Each flight asserts: the vehicle ends safe, watched from the GCS link (Hold armed in the air, or
on the ground disarmed; never disarmed in the air); the real carrier never came within its
guard, b c - carrier.p3_margin_m (7.5 m), of the target (its own summary; b c itself is crossed
by design while it brakes after the separation at b c); the rogue input had no effect (the
separation latched at b c on the real carrier, no pilot_override, nothing sent to the rogue)
and was counted (summary.json); the flight log is complete.
"""
from __future__ import annotations

import json
import math
import random
import socket
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import zenoh

from mission.mavlink import px4
from mission.mavlink.env import mavlink
from tests.faults.procs import DEMO, Flight, assert_safe_end, flight, wait_for
from tests.faults.test_matrix import assert_completed, assert_exit, assert_never_disarmed_in_the_air, concurrently

pytestmark = [pytest.mark.slow, pytest.mark.timeout(200)]
# A class per test: `--dist loadscope` schedules a class as its own unit, so the flights spread over the workers.

# The attacks fly in lockstep (the three processes step on the vehicle's simulated time, so a
# loaded machine can make neither the carrier look lost nor the vehicle see offboard loss), the
# MAVLink ones paced at SPEED (at most SPEED simulated seconds per wall second) so that an attack
# sent when the test reads a phase lands in that phase. Two MAVLink flights are real time at
# SPEED: the wrong key (the vehicle's clock itself, its signed barriers, is what the mission
# refuses) and the rogue sysid (adoption waits on the mission's clock for the rival to fall
# silent, and in lockstep that clock starts only at the adopted vehicle's first barrier).
SPEED = 2.0
PACED = ("--lockstep-max-speed", str(SPEED))

STATE_KEY = "marsupial/pair0/carrier/state"
TARGET = (24.0, 18.0, -5.0)
GUARD_M = 8.0 - 0.5  # b c - carrier.p3_margin_m
KEY_A = bytes.fromhex("a1" * 32)
KEY_B = bytes.fromhex("b2" * 32)


def assert_real_carrier_kept_its_guard(f: Flight) -> float:
    """The carrier's own summary, written when it stopped (call after the flight closed)."""
    closest = f.carrier_summary()["closest_target_distance_m"]
    assert closest is not None and closest >= GUARD_M - 0.05, closest
    return closest


class CarrierWatch:
    """Subscribes to the carrier state key on the router's session: the real carrier's latest
    state (JSON dict) and its Zenoh source id, as any participant of the network sees them."""

    def __init__(self, f: Flight) -> None:
        self.session = f.router.session
        self.source: Any = None
        self.latest: dict[str, Any] | None = None
        self.count = 0  # the real carrier's states seen
        self._lock = threading.Lock()
        self._sub = self.session.declare_subscriber(STATE_KEY, self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        info = sample.source_info
        if info is None or str(info.source_id.zid) == str(self.session.zid()) or len(sample.payload) > 4096:
            return  # ours (the attacker's)
        with self._lock:
            if self.source is None:
                self.source = info.source_id
            if str(info.source_id) == str(self.source):
                state = json.loads(sample.payload.to_bytes())
                self.count += 1
                if self.latest is None or state["seq"] > self.latest["seq"]:
                    self.latest = state

    def state(self) -> dict[str, Any]:
        wait_for(lambda: self.latest is not None, 10.0, "a real carrier state")
        with self._lock:
            return dict(self.latest)  # type: ignore[arg-type]

    def close(self) -> None:
        self._sub.undeclare()


class Attacker:
    """Puts ``make(k)`` (bytes, or None to skip) on the carrier key every ``period_wall_s`` from
    the router's session until stopped; ``source`` spoofs the real carrier's source id. With
    ``every_states`` (and ``watch``), once per that many real carrier states instead: paced on the
    flight's simulated time, so a lockstep flight gets the same number whatever the machine's speed."""

    def __init__(self, f: Flight, make: Callable[[int], bytes | None], period_wall_s: float,
                 source: Callable[[], Any] | None = None, *, every_states: int = 0,
                 watch: CarrierWatch | None = None) -> None:
        self.f, self.make, self.period, self.source = f, make, period_wall_s, source
        self.every, self.watch = every_states, watch
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        session, k = self.f.router.session, 0
        while not self._stop.is_set():
            payload = self.make(k)
            k += 1
            if payload is not None:
                kwargs = {} if self.source is None else {"source_info": zenoh.SourceInfo(self.source(), 10**9 + k)}
                try:
                    session.put(STATE_KEY, payload, **kwargs)
                except zenoh.ZError:  # the flight (and its router) closed first: a failing test
                    return
                self.sent += 1
            if self.every and self.watch is not None:
                due = self.watch.count + self.every  # the next after that many more real states
                while self.watch.count < due and not self._stop.wait(0.002):
                    pass
            else:
                self._stop.wait(self.period)

    def stop(self) -> int:
        self._stop.set()
        self._thread.join(5.0)
        return self.sent


def _state(seq: int, stamp: float, position: list[float], velocity: list[float] | None = None) -> bytes:
    return json.dumps({"stamp": stamp, "seq": seq, "frame": "local_ned", "position": position,
                       "velocity": velocity or [0.0, 0.0, 0.0], "yaw": None}).encode()


# --------------------------------------------------------------------------------------------- Zenoh


def _rogue(tmp_path: Path, name: str, position: list[float]) -> None:
    with flight(tmp_path, name, speed=SPEED, lockstep=True) as f:
        watch = CarrierWatch(f)
        try:
            f.wait_phase("RIDING")
            real = watch.state()
            # one rogue state per two real ones (paced on simulated time, ~180 while riding)
            rogue = Attacker(f, lambda k: _state(10**6 + k, real["stamp"] + 0.2 * k / 5, position), 0.05,
                             every_states=2, watch=watch)
            f.wait_phase("NAVIGATING", 60.0)
            sent = rogue.stop()
        finally:
            watch.close()
        s = assert_completed(f)  # separated at b c (8.0 +- 0.05 m) of the *real* carrier, arrived
        assert s["p1"], s  # P1-P3 all hold with a rogue publisher on the network
        feed = s["carrier_feed"]
        assert sent >= 20 and feed["dropped"]["source"] >= 0.8 * sent, (sent, feed)
        assert sum(feed["rejected_sources"].values()) == feed["dropped"]["source"], feed
        assert feed["bound_source"] is not None and feed["bound_source"] not in feed["rejected_sources"]
    assert_real_carrier_kept_its_guard(f)


class TestARoguePublisher:
    def test_a_rogue_publisher_with_higher_sequence_numbers_is_dropped_and_counted(self, tmp_path: Path) -> None:
        """Measured on main before: every real sample dropped as stale_seq, the UAV flew to the
        rogue's dock point; placed 7 m short of the target the latch fired at once on nothing."""
        short = [24.0 - 4.9 * 0.8, 18.0 - 4.9 * 0.6, 0.0]  # 7.0 m from the target
        assert math.dist(short, TARGET) == pytest.approx(7.0, abs=0.01)
        concurrently(lambda: _rogue(tmp_path, "rogue-far", [-30.0, -40.0, 0.0]),
                     lambda: _rogue(tmp_path, "rogue-short", short))


def _spoofed_outliers(tmp_path: Path) -> None:
    rng = random.Random(11)
    with flight(tmp_path, "outliers", speed=SPEED, lockstep=True) as f:
        watch = CarrierWatch(f)
        try:
            f.wait_phase("RIDING")
            kinds: list[str] = ["hour", "teleport"]

            def outlier(k: int) -> bytes:
                st = watch.state()
                kind = kinds[k] if k < 2 else rng.choice(["hour", "teleport", "speed"])
                pos, vel, stamp = list(st["position"]), list(st["velocity"]), st["stamp"] + 0.001
                if kind == "hour":
                    stamp += 3600.0
                elif kind == "teleport":  # 20 m towards the target: the latch would fire at once
                    d = math.dist(pos[:2], TARGET[:2])
                    pos = [pos[0] + 20.0 * (TARGET[0] - pos[0]) / d, pos[1] + 20.0 * (TARGET[1] - pos[1]) / d, pos[2]]
                else:
                    vel = [25.0, 0.0, 0.0]
                return _state(st["seq"] + 2, stamp, pos, vel)  # ahead of its honest twin

            # one outlier per 40 real carrier states (2.5 %; ~9 while riding): paced on simulated
            # time (a wall period sent 4 on a quiet machine, where the lockstep flight ran faster)
            attacker = Attacker(f, outlier, 0.25, source=lambda: watch.source, every_states=40, watch=watch)
            f.wait_phase("NAVIGATING", 60.0)
            sent = attacker.stop()
        finally:
            watch.close()
        print(f"outliers sent while riding: {sent}")
        s = assert_completed(f)
        assert s["p1"], s  # P1-P3 all hold with 2.5 % outliers
        feed = s["carrier_feed"]
        dropped = feed["dropped"]
        # The hour-ahead state is always a stamp_jump. The teleport is a "jump" unless its honest
        # twin (stamp 1 ms earlier) arrived first and made it stale: which one Zenoh delivers first is
        # not ours to choose, so the reason is checked deterministically in tests/unit/bus/test_feed_gate.py
        # and here only that it was dropped (gated == sent) and the latch held (P1, assert_completed).
        assert sent >= 5 and dropped.get("stamp_jump", 0) >= 1, (sent, feed)
        assert dropped.get("jump", 0) + dropped.get("stale_stamp", 0) >= 1, (sent, feed)
        gated = sum(n for reason, n in dropped.items() if reason != "unbound")
        assert gated == sent, (sent, feed)  # every outlier dropped (one overtaken by its honest twin as stale)
        assert feed["resyncs"] == 0 and feed["rejected_sources"] == {}
    assert_real_carrier_kept_its_guard(f)


def _oversized(tmp_path: Path) -> None:
    with flight(tmp_path, "oversized", speed=SPEED, lockstep=True) as f:
        f.wait_phase("RIDING")
        blob = b"{" + b" " * (10 * 1024 * 1024) + b"}"
        for _ in range(5):  # blocking, not dropped under congestion (Zenoh's default for puts: CI once lost all five)
            f.router.session.put(STATE_KEY, blob, congestion_control=zenoh.CongestionControl.BLOCK)
        s = assert_completed(f)
        feed = s["carrier_feed"]
        assert feed["dropped"].get("size", 0) >= 1, feed
    assert_real_carrier_kept_its_guard(f)


class TestSpoofedOutliers:
    def test_spoofed_outliers_and_oversized_payloads_never_move_the_latch(self, tmp_path: Path) -> None:
        """States spoofed with the real carrier's own source id: one an hour ahead (on main it made
        every later honest state stale_stamp: carrier_lost), one 20 m towards the target (on main it
        fired the latch), then 2.5 % outliers; and five 10 MB payloads (on main: carrier_lost, the
        state 2.45 s old). The mission completes, separating at b c of the real carrier."""
        concurrently(lambda: _spoofed_outliers(tmp_path), lambda: _oversized(tmp_path))


# --------------------------------------------------------------------------------------------- MAVLink


class RogueMavlink:
    """A UDP socket sending MAVLink as ``sysid``/``compid`` (unsigned) to the mission's port; it
    records whatever comes back."""

    def __init__(self, sysid: int, compid: int = 1) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.codec = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)

    def heartbeat(self, port: int, mode: str = "AUTO.LOITER", armed: bool = False) -> None:
        msg = mavlink.MAVLink_heartbeat_message(px4.MAV_TYPE_QUADROTOR, px4.MAV_AUTOPILOT_PX4,
                                                px4.base_mode_of(mode, armed), px4.custom_mode_of(mode), 4, 3)
        self.sock.sendto(msg.pack(self.codec), ("127.0.0.1", port))

    def received(self) -> int:
        n = 0
        while True:
            try:
                self.sock.recv(65535)
                n += 1
            except BlockingIOError:
                return n

    def close(self) -> None:
        self.sock.close()


def _adopting_config(path: Path) -> Path:
    """demo.toml without target_system (the vehicle is adopted from its HEARTBEATs), for a real-time
    flight: the carrier may be 1.5 s old rather than 0.5 (the flight checks what the link
    accepts, not how fast a stalled carrier is noticed: at speed 2 a 0.25 s stall of one process
    on a busy machine aborted it as carrier_lost)."""
    lines = [("carrier_timeout_s = 1.5" if line.startswith("carrier_timeout_s") else line)
             for line in DEMO.read_text().splitlines() if not line.startswith("target_system")]
    path.write_text("\n".join(lines) + "\n")
    return path


def _rogue_sysid_first(tmp_path: Path) -> None:
    config = _adopting_config(tmp_path / "adopt.toml")
    rogue = RogueMavlink(sysid=42)
    stop = threading.Event()
    f_holder: list[Flight] = []

    def first() -> None:  # as soon as the mission listens, before the vehicle process exists
        wait_for(lambda: f_holder and f_holder[0].mav_port and f_holder[0].procs.get("mission") is not None, 30.0)
        f = f_holder[0]
        from tests.faults.procs import udp_bound
        wait_for(lambda: udp_bound(f.mav_port) or stop.is_set(), 30.0)
        for _ in range(2):
            rogue.heartbeat(f.mav_port, "OFFBOARD", armed=True)

    try:
        with flight(tmp_path, "sysid42", config=config, start=False, mission_verbose=True, speed=SPEED) as f:
            f_holder.append(f)
            sender = threading.Thread(target=first, daemon=True)
            sender.start()
            f.start()
            sender.join(10.0)
            s = assert_completed(f)
            assert s["link"]["rejected_foreign"] >= 2, s["link"]
            assert "vehicle adopted after" in f.text("mission.err") and "sysid 1 compid 1" in f.text("mission.err")
            assert rogue.received() == 0  # no HEARTBEAT, setpoint or command ever went to sysid 42's address
        assert_real_carrier_kept_its_guard(f)
    finally:
        stop.set()
        rogue.close()


def _lone_rogue_adopted(tmp_path: Path) -> None:
    """target_system unset; a rogue PX4 (sysid 42) talks alone, 5 HEARTBEATs a second, until the
    mission has adopted it; then the real vehicle starts."""
    config = _adopting_config(tmp_path / "adopt-lone.toml")
    rogue = RogueMavlink(sysid=42)
    stop = threading.Event()

    def rogue_first(f: Flight) -> None:
        def talk() -> None:
            while not stop.wait(0.2):
                rogue.heartbeat(f.mav_port)

        threading.Thread(target=talk, daemon=True).start()
        wait_for(lambda: "vehicle adopted" in f.text("mission.err"), 20.0, "the rogue adopted")

    try:
        with flight(tmp_path, "lone-rogue", config=config, mission_verbose=True, speed=SPEED,
                    before_vehicle=rogue_first) as f:
            f.wait_mission(30.0)
            assert_exit(f, 5, "vehicle_ambiguous")
            err = f.text("mission.err")
            assert "sysid 42 compid 1" in err and "WITHOUT mavlink.target_system" in err  # adopted, loudly
            assert "a second PX4 autopilot (sysid 1 compid 1" in err  # refused once the real one talked
            rows, s = f.record(), f.summary()
            assert (s["phase"], s["reason"]) == ("ABORT", "vehicle_ambiguous") and s["ticks"] == len(rows)
            assert {r["phase"] for r in rows} == {"PREFLIGHT", "ABORT"}  # nothing flown: the rogue has no position
            v = assert_safe_end(f, modes=("landed",))  # the real vehicle: never armed, never commanded
            assert not v["armed"]
        assert f.vehicle_counters()["sp"] == 0  # its last status line, written as it stopped
        assert f.carrier_summary()["closest_target_distance_m"] > 20.0  # no passenger rode: it never moved
    finally:
        stop.set()
        rogue.close()


def _unsigned_spoofs(tmp_path: Path) -> None:
    key = tmp_path / "a.key"
    key.write_text(KEY_A.hex())
    spoofer = RogueMavlink(sysid=1)
    try:
        with flight(tmp_path, "spoofed", vehicle_args=("--signing-key", str(key), *PACED), mission_args=("--signing-key", str(key)),
                    speed=SPEED, lockstep=True) as f:
            f.wait_phase("RIDING")
            for _ in range(5):  # claiming a pilot took over (on main: pilot_override)
                spoofer.heartbeat(f.mav_port, "POSCTL", armed=True)
            for _ in range(20):  # copying the real state (on main: moved the reply address)
                spoofer.heartbeat(f.mav_port, "OFFBOARD", armed=True)
                time.sleep(0.02)
            s = assert_completed(f)
            assert s["link"]["rx_unsigned"] >= 25, s["link"]
            assert s["link"]["rx_bad_signature"] == 0, s["link"]  # each lockstep step's SYSTEM_TIME is signed before what follows it
            assert spoofer.received() == 0
        assert_real_carrier_kept_its_guard(f)
    finally:
        spoofer.close()


def _wrong_key(tmp_path: Path) -> None:
    a, b = tmp_path / "a2.key", tmp_path / "b.key"
    a.write_text(KEY_A.hex())
    b.write_text(KEY_B.hex())
    with flight(tmp_path, "wrong-key", vehicle_args=("--signing-key", str(b)), mission_args=("--signing-key", str(a)), speed=SPEED) as f:
        f.wait_mission(60.0)
        assert_exit(f, 5, "signing_mismatch")
        assert "signs with another key" in f.text("mission.err")
        rows, s = f.record(), f.summary()  # the log is complete; its tlog is empty: nothing was ever sent
        assert rows and rows[-1]["phase"] == "ABORT" and s["ticks"] == len(rows)
        assert (s["phase"], s["reason"]) == ("ABORT", "signing_mismatch"), s
        assert s["link"]["rx_bad_signature"] > 0 and s["link"]["tx_messages"] == 0, s["link"]
        assert (f.log_dir / "flight.tlog").stat().st_size == 0  # no peer address ever: not even a HEARTBEAT
        v = assert_safe_end(f, modes=("landed",))  # never armed: on the ground, disarmed
        assert not v["armed"]
        assert_never_disarmed_in_the_air(f)
    assert f.carrier_summary()["closest_target_distance_m"] > 20.0  # it never left: no passenger rode


class TestRogueMavlink:
    def test_rogue_mavlink_system_spoofed_heartbeats_and_a_wrong_key(self, tmp_path: Path) -> None:
        """A sysid 42 PX4 HEARTBEAT first (on main: adopted as the vehicle, setpoints and arming sent
        to it); with signing on, unsigned HEARTBEATs claiming POSCTL or copying the vehicle (on main:
        pilot_override, reply address moved); a vehicle signing with another key (on main:
        a mislabelled "carrier_lost", now its own reason); a rogue talking alone until adopted, then
        the real vehicle (on main: 1654 setpoints and 48 commands went to a rogue adopted this way;
        now adopted with a warning, and the mission aborts vehicle_ambiguous at the real vehicle's
        first HEARTBEAT, having sent nothing but its own HEARTBEATs)."""
        concurrently(lambda: _rogue_sysid_first(tmp_path), lambda: _unsigned_spoofs(tmp_path))
        concurrently(lambda: _wrong_key(tmp_path), lambda: _lone_rogue_adopted(tmp_path))
