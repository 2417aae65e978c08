"""The carrier enforces P3 itself. Whatever the passenger does (never separates,
lies about its phase, vanishes), the carrier's own controller never brings it closer to the
target than b c - carrier.p3_margin_m. Real Zenoh between the carrier and a scripted passenger;
the carrier steps on a manual clock."""
from __future__ import annotations

import numpy as np
import pytest

from mission.time.clock import ManualClock
from mission.config.schema import Config, from_dict
from mission.bus.wire import PassengerStatus
from mission.carrier.controller import CarrierController
from mission.carrier.backends.sim import SimRobot
from mission.phases.phase import Phase
from sim.robots.carrier import CarrierMode, CarrierSim
from tests.integration.carrier.test_carrier_sim import TARGET, Passenger, _seen, sessions
from tests.support.zenoh_util import wait_for

pytestmark = pytest.mark.timeout(60)

DT = 1.0 / 30.0
RADIUS = 8.0 - 0.5  # b c - p3_margin_m


def _cfg(**carrier: object) -> Config:
    mode = carrier.pop("carrier_mode", "stop")
    return from_dict({
        "zenoh": {"pair": "p3"},
        "scenario": {"carrier_start": [0.0, 0.0, 0.0], "target": TARGET.tolist(), "carrier_mode": mode},
        "safety": {"carrier_max_accel_m_s2": 1.0},
        "carrier": {"rate_hz": 30.0, "max_speed_m_s": 3.0, "passenger_timeout_s": 1.0, "p3_margin_m": 0.5, **carrier},
    })


def _drive(sim: CarrierSim, clock: ManualClock, passenger: Passenger, script: dict[int, str], steps: int,
           refresh: str | None) -> list[float]:
    """Step the carrier ``steps`` times; at step k the passenger says ``script[k]`` (waited for);
    every 10 steps it repeats ``refresh`` (None: silence). Returns |e_tc| [m] after every step."""
    distances = []
    for k in range(steps):
        say = script.get(k) or (refresh if refresh and k % 10 == 0 else None)
        if say:
            seq = passenger.say(say)
            wait_for(lambda: _seen(sim, seq), what=f"{say} seen")
        clock.advance(DT)
        sim.step(DT)
        distances.append(float(np.linalg.norm(TARGET - np.pad(sim.position_m, (0, 3 - sim.position_m.shape[0])))))
    return distances


@pytest.mark.parametrize("kinematics", ["holonomic", "diff_drive", "ackermann"])
def test_a_passenger_that_never_separates_cannot_bring_the_carrier_inside_the_guard(kinematics: str) -> None:
    clock = ManualClock()
    with sessions(1) as (sa, sb), CarrierSim(_cfg(kinematics=kinematics), clock, sa) as sim:
        passenger = Passenger(sb, "p3", clock, sim)
        try:
            wait_for(lambda: passenger.pub.matched)
            d = _drive(sim, clock, passenger, {0: "RIDING"}, 30 * 40, refresh="RIDING")
        finally:
            passenger.pub.close()
        assert sim.mode is CarrierMode.APPROACHING  # it still believes the passenger rides
    assert min(d) >= RADIUS - 1e-9, min(d)
    assert d[-1] < RADIUS + 0.1  # it got there: the guard stops it at the circle, not early
    assert sim.summary()["guard_active_ticks"] > 0


def test_a_lying_separated_phase_under_remark1_does_not_carry_the_carrier_into_the_target() -> None:
    """Remark 1: after separation the carrier keeps its velocity of that instant. A passenger that
    says SEPARATED while the carrier is still far away would send it straight on through the
    target; the guard stops it at the circle (it may slide along it, never inside)."""
    clock = ManualClock()
    with sessions(1) as (sa, sb), CarrierSim(_cfg(carrier_mode="remark1"), clock, sa) as sim:
        passenger = Passenger(sb, "p3", clock, sim)
        try:
            wait_for(lambda: passenger.pub.matched)
            d = _drive(sim, clock, passenger, {0: "RIDING", 60: "SEPARATED"}, 30 * 30, refresh=None)
        finally:
            passenger.pub.close()
        assert sim.mode is CarrierMode.SEPARATED
    assert d[60] > 12.0  # the lie came far from the target
    assert min(d) >= RADIUS - 1e-9, min(d)


def test_a_phase_that_jumps_back_to_riding_does_not_restart_the_approach() -> None:
    clock = ManualClock()
    with sessions(1) as (sa, sb), CarrierSim(_cfg(), clock, sa) as sim:
        passenger = Passenger(sb, "p3", clock, sim)
        try:
            wait_for(lambda: passenger.pub.matched)
            d = _drive(sim, clock, passenger, {0: "RIDING", 90: "SEPARATED", 100: "RIDING"}, 400, refresh="RIDING")
        finally:
            passenger.pub.close()
    assert sim.mode is CarrierMode.SEPARATED
    assert d[-1] == pytest.approx(d[250], abs=1e-9)  # stopped for good after braking (3 s at 1 m/s^2)
    assert min(d) >= RADIUS - 1e-9


def test_a_passenger_that_vanishes_stops_the_carrier_outside_the_guard() -> None:
    clock = ManualClock()
    with sessions(1) as (sa, sb), CarrierSim(_cfg(), clock, sa) as sim:
        passenger = Passenger(sb, "p3", clock, sim)
        try:
            wait_for(lambda: passenger.pub.matched)
            d = _drive(sim, clock, passenger, {0: "RIDING"}, 120, refresh="RIDING")
            assert sim.mode is CarrierMode.APPROACHING
        finally:
            passenger.pub.close()  # the passenger's process dies: its token goes too
        wait_for(lambda: sim.passenger.alive is False, what="token gone")
        d += _drive(sim, clock, passenger, {}, 30 * 20, refresh=None)
        assert sim.mode is CarrierMode.PAUSED
    assert d[-1] == pytest.approx(d[-30], abs=1e-9)  # standing still
    assert min(d) >= RADIUS - 1e-9


def test_deck_alignment_moves_the_carrier_onto_the_passenger_once_and_only_so_far() -> None:
    """carrier.align_on_deck_m: two estimators disagree; while the passenger stands on the deck
    the carrier shifts its horizontal estimate onto the passenger's (at most that far), once, and
    publishes nothing before (the passenger waits for it)."""
    clock = ManualClock()
    cfg = from_dict({**_cfg().model_dump(), "carrier": {**_cfg().carrier.model_dump(), "align_on_deck_m": 1.0}})
    with sessions(1) as (sa, sb), CarrierSim(cfg, clock, sa) as sim:
        passenger = Passenger(sb, "p3", clock, sim)
        try:
            wait_for(lambda: passenger.pub.matched)
            assert sim.step(0.0) is not None and sim.seq == 0  # not published: not aligned yet
            for seq in (1, 2, 3):  # the passenger's first statuses bind it (mission.bus.feeds.PassengerFeed)
                passenger.pub.publish(PassengerStatus("PREFLIGHT", clock.now(), seq, [0.6, -0.3, 0.0], [0, 0, 0]))
            wait_for(lambda: _seen(sim, 3))
            clock.advance(DT)
            out = sim.step(DT)
            assert sim.seq == 1 and out.position.tolist() == pytest.approx([0.6, -0.3, 0.0])
            passenger.pub.publish(PassengerStatus("ARMING", clock.now(), 4, [5.0, 5.0, 0.0], [0, 0, 0]))
            wait_for(lambda: _seen(sim, 4))
            clock.advance(DT)
            assert sim.step(DT).position.tolist() == pytest.approx([0.6, -0.3, 0.0])  # once only
        finally:
            passenger.pub.close()
    far = from_dict({**cfg.model_dump(), "carrier": {**cfg.carrier.model_dump(), "align_on_deck_m": 0.5}})
    clock = ManualClock()
    with sessions(1) as (sa, sb), CarrierSim(far, clock, sa) as sim:
        passenger = Passenger(sb, "p3", clock, sim)
        try:
            wait_for(lambda: passenger.pub.matched)
            for seq in (1, 2, 3):
                passenger.pub.publish(PassengerStatus("PREFLIGHT", clock.now(), seq, [0.6, -0.3, 0.0], [0, 0, 0]))
            wait_for(lambda: _seen(sim, 3))
            assert sim.step(DT).position.tolist() == pytest.approx([0.0, 0.0, 0.0])  # 0.67 m > 0.5: refused
            assert sim.summary()["deck_alignment_m"] == [0.0, 0.0, 0.0]
        finally:
            passenger.pub.close()


class OvershootingRobot(SimRobot):
    """A diff-drive robot whose speed loop runs 35 % fast, as the SIH rover ran 2.7 m/s for 2."""

    def command(self, cmd):  # type: ignore[no-untyped-def]
        super().command(cmd)
        self.speed_m_s *= 1.35


@pytest.mark.parametrize("tau", [0.0, 1.0])
def test_speed_calibration_holds_an_overshooting_robot_at_the_law_s_speed_and_the_guard_holds(tau: float) -> None:
    clock = ManualClock()
    cfg = _cfg(kinematics="diff_drive", speed_ratio_tau_s=tau, max_speed_m_s=2.0)
    with sessions(1) as (sa, sb):
        robot = OvershootingRobot(cfg, clock)
        with CarrierController(cfg, clock, sa, robot) as ctl:
            passenger = Passenger(sb, "p3", clock, ctl)
            speeds, d = [], []
            try:
                wait_for(lambda: passenger.pub.matched)
                for k in range(30 * 25):
                    if k % 10 == 0:
                        seq = passenger.say("RIDING")
                        wait_for(lambda: ctl.passenger.latest() is not None and ctl.passenger.latest().status.seq == seq)
                    clock.advance(DT)
                    ctl.step(DT)
                    speeds.append(robot.speed_m_s)
                    d.append(float(np.linalg.norm(TARGET - robot.position_m)))
            finally:
                passenger.pub.close()
    if tau == 0.0:
        assert max(speeds[:300]) == pytest.approx(2.0 * 1.35, abs=0.01)  # the overshoot, unchecked
    else:
        assert max(speeds[200:300]) == pytest.approx(2.0, abs=0.05)  # cruising at the law's speed
        assert max(speeds[:300]) < 2.0 * 1.35 - 0.3  # it never ran as fast as unchecked
    # A robot faster than told can enter the circle by at most the overspeed tolerance held for
    # a period (0.1 m/s x 1/30 s = 3 mm) before the guard's measured-speed brake catches it.
    assert min(d) >= RADIUS - 0.1 * DT


class SharingPassenger(Passenger):
    """A passenger whose statuses share the frames' bias (``bias``; None: its estimate not
    converged, none shared), as a relnav passenger's do."""

    bias: np.ndarray | None = None

    def _send(self, phase: str) -> int:
        self.seq += 1
        dock = self.carrier.dock_point_ned_m() if self.carrier is not None else None
        at = [0.0, 0.0, -1.5] if dock is None else dock
        shared = {} if self.bias is None else {"bias_ned_m": self.bias, "bias_sigma_m": 0.2}
        self.pub.publish(PassengerStatus(phase, self.clock.now(), self.seq, at, [0, 0, 0], Phase(phase).separated,
                                         **shared))  # type: ignore[arg-type]
        return self.seq


def test_the_guard_holds_in_the_passengers_frame_by_the_bias_it_shares_and_widens_once_it_goes_stale() -> None:
    """carrier.p3_frame = "passenger": a passenger that never separates, riding, shares a bias that
    puts the carrier 1.5 m nearer the target in its frame than in the carrier's own; over real Zenoh
    the carrier parks at b c - p3_margin_m from the target in the passenger's frame (1.5 m farther in
    its own). Then the passenger stops sharing it: p3_bias_max_age_s later the guard falls back to
    the carrier's own frame with the margin widened by p3_unaligned_margin_m, and the carrier
    drives on to that circle; the fall back is counted in its summary."""
    toward = np.array([TARGET[0], TARGET[1], 0.0]) / float(np.hypot(TARGET[0], TARGET[1]))
    bias = -1.5 * toward  # the carrier's GNSS frame minus the passenger's
    clock = ManualClock()
    cfg = _cfg(p3_frame="passenger", p3_unaligned_margin_m=2.0, p3_bias_max_age_s=1.0)
    with sessions(1) as (sa, sb), CarrierSim(cfg, clock, sa) as sim:
        passenger = SharingPassenger(sb, "p3", clock, sim)
        passenger.bias = bias
        try:
            wait_for(lambda: passenger.pub.matched)
            _drive(sim, clock, passenger, {0: "RIDING"}, 30 * 40, refresh="RIDING")
            x = np.pad(sim.position_m, (0, 3 - sim.position_m.shape[0]))
            frame = sim.summary()["p3_frame"]
            passenger.bias = None  # its marker lost: statuses without the bias
            d = _drive(sim, clock, passenger, {}, 30 * 30, refresh="RIDING")
            summary = sim.summary()["p3_frame"]
        finally:
            passenger.pub.close()
        assert sim.mode is CarrierMode.APPROACHING
    assert frame["passenger"] is True and frame["fallbacks"]["stale"] == 0
    in_passenger = float(np.linalg.norm(TARGET - (x - bias)))
    assert RADIUS - 1e-9 <= in_passenger < RADIUS + 0.1  # at the guard's circle where the target is
    assert float(np.linalg.norm(TARGET - x)) > RADIUS + 1.2  # and short of it in its own frame
    assert frame["closest_target_distance_m"] == pytest.approx(in_passenger, abs=0.05)
    assert summary["passenger"] is False and summary["why"] == "stale" and summary["fallbacks"]["stale"] == 1
    assert RADIUS - 2.0 - 1e-9 <= min(d) and d[-1] < RADIUS - 2.0 + 0.1  # its own frame, 2 m nearer
