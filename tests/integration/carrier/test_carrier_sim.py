"""The carrier simulator over real Zenoh: waits for the passenger, drives towards the target with
the paper's law while the passenger rides, stops after separation (or keeps its velocity under
Remark 1), and stops when the passenger goes silent or vanishes. Plus its command line."""
from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import zenoh

from mission.bus.auth import BusAuth
from mission.bus.bridge import CarrierFeed, PassengerPublisher, keys
from mission.cli import main as cli_main
from mission.time.clock import Clock, LockstepClock, ManualClock, ScaledClock
from mission.config.schema import Config, from_dict
from mission.bus.wire import CarrierState, PassengerStatus, decode_carrier_json
from mission.phases.phase import Phase
from mission.carrier.controller import CarrierController
from mission.carrier.modes import BEFORE_RIDING
from sim.robots.carrier import CarrierMode, CarrierSim
from tests.support.stepper import Stepper
from tests.support.zenoh_util import endpoint, free_port, peer, wait_for
from tests.conftest import FLIGHT_TOML, ROOT

pytestmark = pytest.mark.timeout(30)

TARGET = np.array([20.0, 15.0, -4.0])


def _cfg(pair: str = "sim", **scenario: object) -> Config:
    return from_dict({
        "zenoh": {"pair": pair},
        "scenario": {"carrier_start": [0.0, 0.0, 0.0], "target": TARGET.tolist(), **scenario},
        "carrier": {"rate_hz": 30.0, "max_speed_m_s": 3.0, "passenger_timeout_s": 1.0},
    })


class Passenger:
    """The test's stand-in for the mission controller: publishes statuses with its own seq. It
    stands on the deck first (three PREFLIGHT statuses before its first later phase: the carrier
    binds only a passenger that began there) and says it is on ``carrier``'s dock point (without a
    carrier: 1.5 m above the origin)."""

    def __init__(self, session: zenoh.Session, pair: str, clock: Clock, carrier: CarrierController | None = None,
                 auth: BusAuth | None = None) -> None:
        # blocking, never dropped: the statuses of a boarding go out back to back
        self.pub = PassengerPublisher(session, pair, zenoh.CongestionControl.BLOCK, auth=auth)
        self.clock, self.seq, self.carrier = clock, 0, carrier
        self.on_deck = 0  # statuses sent before riding

    def say(self, phase: str) -> int:
        if phase in BEFORE_RIDING:
            self.on_deck += 1
        while self.on_deck < 3:
            self.on_deck += 1
            self._send("PREFLIGHT")
        return self._send(phase)

    def _send(self, phase: str) -> int:
        self.seq += 1
        separated = Phase(phase).separated
        dock = self.carrier.dock_point_ned_m() if self.carrier is not None else None
        at = [0.0, 0.0, -1.5] if dock is None else dock
        self.pub.publish(PassengerStatus(phase, self.clock.now(), self.seq, at, [0, 0, 0], separated))
        return self.seq


class Recorder:
    """Every carrier state published on the pair's key, in arrival order (thread-safe)."""

    def __init__(self, session: zenoh.Session, pair: str) -> None:
        self._lock = threading.Lock()
        self._states: list[CarrierState] = []
        self.sub = session.declare_subscriber(keys(pair).carrier_state, self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        s = decode_carrier_json(sample.payload.to_bytes())
        with self._lock:
            self._states.append(s)

    @property
    def states(self) -> list[CarrierState]:
        with self._lock:
            return list(self._states)


@contextlib.contextmanager
def sessions(n_clients: int = 2) -> Iterator[list[zenoh.Session]]:
    """A listening session (the simulator's) and ``n_clients`` sessions connected to it."""
    ep = endpoint(free_port())
    out = [peer(listen=[ep])]
    try:
        for _ in range(n_clients):
            out.append(peer(connect=[ep]))
        for s in out[1:]:
            wait_for(lambda s=s: len(list(s.info.peers_zid())) > 0, what="connected")
        yield out
    finally:
        for s in reversed(out):
            s.close()


@contextlib.contextmanager
def running(sim: CarrierSim, clock: Clock | None = None) -> Iterator[threading.Event]:
    stop = threading.Event()
    thread = threading.Thread(target=sim.run, args=(stop,), name="carrier-sim")
    thread.start()
    try:
        yield stop
    finally:
        stop.set()
        if isinstance(clock, LockstepClock):
            clock.close()  # its sleep ends now
        thread.join(timeout=5)
        assert not thread.is_alive()


def _seen(sim: CarrierSim, seq: int) -> bool:
    rx = sim.passenger.latest()
    return rx is not None and rx.status.seq == seq


def test_step_by_step_waits_drives_towards_the_target_and_stops_after_separation() -> None:
    clock = ManualClock()
    dt = 1.0 / 30.0
    with sessions(1) as (sa, sb), CarrierSim(_cfg(), clock, sa) as sim, \
            CarrierFeed(sb, "sim", clock) as observer:
        passenger = Passenger(sb, "sim", clock, sim)
        try:
            wait_for(lambda: sim.publisher.matched, what="observer subscribed")
            first = sim.step(0.0)
            assert sim.mode is CarrierMode.WAITING
            np.testing.assert_array_equal(first.position, [0.0, 0.0, 0.0])
            np.testing.assert_array_equal(first.velocity_ned_m_s, [0.0, 0.0, 0.0])
            wait_for(lambda: passenger.pub.matched)
            seq = passenger.say("JOIN")
            wait_for(lambda: _seen(sim, seq), what="JOIN seen")
            for _ in range(3):
                clock.advance(dt)
                s = sim.step(dt)
                assert sim.mode is CarrierMode.WAITING and not s.velocity_ned_m_s.any()

            seq = passenger.say("RIDING")
            wait_for(lambda: _seen(sim, seq), what="RIDING seen")
            states = []
            for _ in range(20):
                clock.advance(dt)
                states.append(sim.step(dt))
            assert sim.mode is CarrierMode.APPROACHING
            dist = [np.linalg.norm((TARGET - s.position)[:2]) for s in states]
            assert all(b < a for a, b in zip(dist, dist[1:]))  # monotonically closer
            for s in states:
                assert s.position[2] == 0.0 and s.velocity_ned_m_s[2] == 0.0  # planar carrier
                assert np.linalg.norm(s.velocity_ned_m_s) <= 3.0 + 1e-9  # carrier.max_speed_m_s
                e_tc = (TARGET - s.position)[:2]
                heading = s.velocity_ned_m_s[:2] / np.linalg.norm(s.velocity_ned_m_s[:2])
                np.testing.assert_allclose(heading, e_tc / np.linalg.norm(e_tc), atol=1e-9)  # u_c ∥ e_tc
            # position integrates the held command
            np.testing.assert_allclose(states[-1].position, states[-2].position + states[-2].velocity_ned_m_s * dt)
            # published as returned (the observer may miss a sample: publishers drop under congestion)
            rx = wait_for(lambda: (r := observer.latest()) is not None and r.state.seq >= states[0].seq and r)
            sent = {s.seq: s for s in states}
            np.testing.assert_array_equal(rx.state.position, sent[rx.state.seq].position)
            np.testing.assert_array_equal(rx.state.velocity_ned_m_s, sent[rx.state.seq].velocity_ned_m_s)

            seq = passenger.say("SEPARATED")
            wait_for(lambda: _seen(sim, seq), what="SEPARATED seen")
            clock.advance(dt)
            stop = sim.step(dt)
            assert sim.mode is CarrierMode.SEPARATED
            assert not stop.velocity_ned_m_s.any()
            for _ in range(5):
                clock.advance(dt)
                np.testing.assert_array_equal(sim.step(dt).position, stop.position)
            # latched: a later RIDING does not restart the approach
            seq = passenger.say("RIDING")
            wait_for(lambda: _seen(sim, seq))
            clock.advance(dt)
            assert not sim.step(dt).velocity_ned_m_s.any() and sim.mode is CarrierMode.SEPARATED
        finally:
            passenger.pub.close()


def test_remark1_keeps_the_velocity_of_the_separation_instant() -> None:
    clock = ManualClock()
    dt = 1.0 / 30.0
    with sessions(1) as (sa, sb), CarrierSim(_cfg(carrier_mode="remark1"), clock, sa) as sim:
        passenger = Passenger(sb, "sim", clock, sim)
        try:
            sim.step(0.0)
            wait_for(lambda: passenger.pub.matched)
            seq = passenger.say("RIDING")
            wait_for(lambda: _seen(sim, seq))
            for _ in range(5):
                clock.advance(dt)
                before = sim.step(dt)
            seq = passenger.say("NAVIGATING")
            wait_for(lambda: _seen(sim, seq))  # any phase after separation
            after = []
            for _ in range(5):
                clock.advance(dt)
                after.append(sim.step(dt))
            assert sim.mode is CarrierMode.SEPARATED
            for s in after:
                np.testing.assert_allclose(s.velocity_ned_m_s, before.velocity_ned_m_s, atol=1e-12)
            np.testing.assert_allclose(after[-1].position - after[-2].position, before.velocity_ned_m_s * dt, atol=1e-12)
        finally:
            passenger.pub.close()


def test_abort_before_separation_stops_for_good() -> None:
    clock = ManualClock()
    dt = 1.0 / 30.0
    with sessions(1) as (sa, sb), CarrierSim(_cfg(), clock, sa) as sim:
        passenger = Passenger(sb, "sim", clock, sim)
        try:
            sim.step(0.0)
            wait_for(lambda: passenger.pub.matched)
            seq = passenger.say("RIDING")
            wait_for(lambda: _seen(sim, seq))
            clock.advance(dt)
            assert sim.step(dt).velocity_ned_m_s.any()
            seq = passenger.say("ABORT")
            wait_for(lambda: _seen(sim, seq))
            clock.advance(dt)
            assert not sim.step(dt).velocity_ned_m_s.any() and sim.mode is CarrierMode.STOPPED
            seq = passenger.say("RIDING")
            wait_for(lambda: _seen(sim, seq))
            clock.advance(dt)
            assert not sim.step(dt).velocity_ned_m_s.any() and sim.mode is CarrierMode.STOPPED
        finally:
            passenger.pub.close()


def test_2d_scenario_publishes_3d_states_at_down_zero() -> None:
    clock = ManualClock()
    cfg = from_dict({"zenoh": {"pair": "flat"}, "scenario": {"dim": 2, "carrier_start": [1.0, 2.0], "target": [20.0, 15.0]}})
    with sessions(1) as (sa, sb), CarrierSim(cfg, clock, sa) as sim:
        passenger = Passenger(sb, "flat", clock, sim)
        try:
            assert sim.step(0.0).position.tolist() == [1.0, 2.0, 0.0]
            wait_for(lambda: passenger.pub.matched)
            seq = passenger.say("RIDING")
            wait_for(lambda: _seen(sim, seq))
            clock.advance(0.1)
            s = sim.step(0.1)
            assert s.velocity_ned_m_s.shape == (3,) and s.velocity_ned_m_s[2] == 0.0 and s.velocity_ned_m_s[0] > 0
        finally:
            passenger.pub.close()


def test_cdr_carrier_on_a_ros_key_reaches_a_feed_configured_the_same_way() -> None:
    clock = ManualClock()
    cfg = from_dict({"zenoh": {"pair": "ros", "encoding": "cdr", "carrier_key": "robot1/odom"},
                     "scenario": {"carrier_start": [3.0, 4.0, 0.0], "target": TARGET.tolist()}})
    with sessions(1) as (sa, sb), CarrierSim(cfg, clock, sa) as sim, \
            CarrierFeed.from_section(sb, cfg.zenoh, clock, max_age_s=0.5) as feed:
        passenger = Passenger(sb, "ros", clock, sim)
        try:
            wait_for(lambda: sim.publisher.matched)
            wait_for(lambda: passenger.pub.matched)
            seq = passenger.say("RIDING")
            wait_for(lambda: _seen(sim, seq))
            sent = {}

            def got_one() -> bool:
                clock.advance(0.1)
                s = sim.step(0.1)
                sent[round(s.stamp_s, 6)] = s
                rx = feed.latest()
                return rx is not None and rx.state.velocity_ned_m_s.any()

            wait_for(got_one)
            rx = feed.latest()
            assert rx is not None and rx.key == "robot1/odom"
            ref = sent[round(rx.state.stamp_s, 6)]  # Odometry carries the stamp, not the seq
            np.testing.assert_allclose(rx.state.position, ref.position, atol=1e-9)
            np.testing.assert_allclose(rx.state.velocity_ned_m_s, ref.velocity_ned_m_s, atol=1e-9)
            assert rx.state.yaw_rad == pytest.approx(ref.yaw_rad)
        finally:
            passenger.pub.close()


def test_running_carrier_stops_within_one_period_after_separated() -> None:
    """In lockstep (the test steps the carrier's clock): the status arrives between two steps,
    and the carrier's next step is its last in motion."""
    clock = LockstepClock(speed=2.0, name="carrier", creator_runs=False)
    stepper = Stepper(clock)
    with sessions(1) as (sa, sb), CarrierSim(_cfg(), clock, sa) as sim:
        period = sim.period_s
        recorder = Recorder(sb, "sim")
        passenger = Passenger(sb, "sim", clock, sim)
        try:
            wait_for(lambda: sim.publisher.matched, what="recorder subscribed")
            with running(sim, clock):
                wait_for(lambda: passenger.pub.matched)

                def riding_and_moving() -> bool:  # a status each step, there before the next one
                    seq = passenger.say("RIDING")
                    wait_for(lambda: _seen(sim, seq), what="RIDING received")
                    st = recorder.states
                    return len(st) > 0 and np.linalg.norm(st[-1].position) > 0.5

                stepper.until(riding_and_moving, 30, "carrier moving")
                seq = passenger.say("SEPARATED")
                wait_for(lambda: _seen(sim, seq), what="SEPARATED received")  # between two steps: time stands still
                rx_time = sim.passenger.latest().rx_time_s  # type: ignore[union-attr]
                stepper.until(lambda: sum(s.stamp_s > rx_time + 4 * period for s in recorder.states) >= 3, 5,
                              "states after the stop")
            states = recorder.states
        finally:
            recorder.sub.undeclare()
            passenger.pub.close()
    before = [s for s in states if s.stamp_s <= rx_time]
    after = [s for s in states if s.stamp_s >= rx_time + period]
    assert before[-1].velocity_ned_m_s.any()
    stop_position = after[0].position
    for s in after:  # from one period after the status arrived: stopped, not moving
        assert not s.velocity_ned_m_s.any()
        np.testing.assert_array_equal(s.position, stop_position)
    travelled = np.linalg.norm(stop_position - before[-1].position)
    assert travelled <= 3.0 * period * 1.5 + 1e-9  # at most about one period of motion at <= 3 m/s


def test_running_carrier_stops_when_the_passenger_goes_silent_or_vanishes() -> None:
    """In lockstep: silence is measured in simulated time; a vanished token is seen (a Zenoh
    event, waited for while time stands still) before the next step."""
    clock = LockstepClock(speed=2.0, name="carrier", creator_runs=False)
    stepper = Stepper(clock)
    with sessions(2) as (sa, sb, sc), CarrierSim(_cfg(), clock, sa) as sim:
        recorder = Recorder(sb, "sim")
        passenger = Passenger(sc, "sim", clock, sim)

        def say_riding() -> None:
            seq = passenger.say("RIDING")
            wait_for(lambda: _seen(sim, seq), what="RIDING received")

        try:
            wait_for(lambda: sim.publisher.matched, what="recorder subscribed")
            with running(sim, clock):
                wait_for(lambda: passenger.pub.matched)
                say_riding()
                stepper.until(lambda: sim.mode is CarrierMode.APPROACHING, 5, "approaching")
                last_rx = sim.passenger.latest().rx_time_s  # type: ignore[union-attr]
                # silence (the token stays): the status goes stale after passenger_timeout_s
                stepper.until(lambda: sim.mode is CarrierMode.PAUSED, 5, "paused on silence")
                paused_at = clock.now()
                assert 1.0 <= paused_at - last_rx <= 1.0 + 2 * sim.period_s  # at the timeout, not before
                stepper.until(lambda: any(s.stamp_s > paused_at and not s.velocity_ned_m_s.any()
                                          for s in recorder.states), 5, "published stop")
                # the passenger speaks again while riding: the approach resumes
                say_riding()
                stepper.until(lambda: sim.mode is CarrierMode.APPROACHING, 5, "resumed")
                # the passenger's process dies: its token goes at once, well before a timeout
                passenger.pub.close()
                sc.close()
                gone_at = clock.now()
                wait_for(lambda: sim.passenger.alive is False, what="token gone")
                stepper.until(lambda: sim.mode is CarrierMode.PAUSED, 5, "paused on lost token")
                assert clock.now() - gone_at <= 2 * sim.period_s  # its next step, not a timeout later
                stop_at = clock.now()
                stepper.until(lambda: any(s.stamp_s >= stop_at and not s.velocity_ned_m_s.any()
                                          for s in recorder.states), 5, "published stop")
        finally:
            recorder.sub.undeclare()
            passenger.pub.close()


REPO = ROOT


def test_cli_config_error_exits_2(tmp_path: Path) -> None:
    assert cli_main(["carrier", str(tmp_path / "missing.toml")]) == 2
    bad = tmp_path / "bad.toml"
    bad.write_text("[carrier]\nrate_hz = -5\n")
    assert cli_main(["carrier", str(bad)]) == 2
    empty = tmp_path / "empty.toml"
    empty.write_text("")  # no target, no limits: refused
    assert cli_main(["carrier", str(empty)]) == 2
    good = tmp_path / "good.toml"
    good.write_text(FLIGHT_TOML)
    assert cli_main(["carrier", str(good), "--pair", "no/slash"]) == 2


def test_cli_runs_publishes_and_exits_0_on_sigterm(tmp_path: Path) -> None:
    cfg = tmp_path / "carrier.toml"
    cfg.write_text(FLIGHT_TOML.replace("[scenario]\n", "[scenario]\ncarrier_start = [1.0, 2.0, 0.0]\n") + '[zenoh]\npair = "cli"\n')
    ep = endpoint(free_port())
    proc = subprocess.Popen(
        [sys.executable, "-m", "mission.cli", "-v", "carrier", str(cfg), "--zenoh-listen", ep, "--speed", "2"],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONWARNINGS": "error"},
    )
    try:
        observer = wait_for(lambda: _try_connect(ep), timeout_s=15.0, what="carrier process listening")
        try:
            with CarrierFeed(observer, "cli", ScaledClock()) as feed:
                rx = wait_for(feed.latest, timeout_s=10.0, what="a state from the process")
                np.testing.assert_array_equal(rx.state.position, [1.0, 2.0, 0.0])
                assert wait_for(lambda: feed.alive, what="carrier token") is True
                proc.send_signal(signal.SIGTERM)
                _, err = proc.communicate(timeout=10)
                assert proc.returncode == 0, err
                wait_for(lambda: feed.alive is False, what="token gone after exit")
        finally:
            observer.close()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert "SIGTERM" in err


def _try_connect(ep: str) -> zenoh.Session | None:
    from mission.errors import BusError

    try:
        s = peer(connect=[ep], mode="client")  # a client fails fast when nobody listens yet
    except BusError:
        return None
    return s
