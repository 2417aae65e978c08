"""The carrier cooperates in the recovery. While the passenger comes home it drives its steady
recovery course (through the filter, the limits and the P3 guard), parks for good once the
passenger is home, stops while it cannot hear the passenger, and drives again for the next
target. Real Zenoh between the carrier and a scripted passenger; the carrier steps on a manual
clock."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mission.time.clock import ManualClock
from mission.config.schema import Config
from sim.robots.carrier import CarrierMode, CarrierSim
from tests.integration.carrier.test_carrier_p3 import DT, RADIUS, _cfg
from tests.integration.carrier.test_carrier_sim import TARGET, Passenger, _seen, sessions
from tests.support.zenoh_util import wait_for

pytestmark = pytest.mark.timeout(60)

ACCEL = 1.0  # [m/s^2] safety.carrier_max_accel_m_s2 of _cfg


class Run:
    """The carrier stepped tick by tick while a scripted passenger speaks; every tick's planar
    velocity [m/s], position [m], mode and distance to the target [m] kept."""

    def __init__(self, sim: CarrierSim, clock: ManualClock, passenger: Passenger) -> None:
        self.sim, self.clock, self.passenger = sim, clock, passenger
        self.v: list[np.ndarray] = []
        self.x: list[np.ndarray] = []
        self.modes: list[CarrierMode] = []
        self.distances: list[float] = []

    def drive(self, steps: int, say: str | None = None) -> None:
        """``steps`` ticks, the passenger repeating ``say`` every 10 (None: silence)."""
        for k in range(steps):
            if say and k % 10 == 0:
                seq = self.passenger.say(say)
                wait_for(lambda: _seen(self.sim, seq), what=f"{say} seen")
            self.clock.advance(DT)
            out = self.sim.step(DT)
            assert out is not None
            self.v.append(np.array(out.velocity_ned_m_s[:2]))
            self.x.append(np.array(out.position[:2]))
            self.modes.append(self.sim.mode)
            self.distances.append(float(np.linalg.norm(TARGET - out.position)))

    def deploy(self) -> None:
        """Ride 3 s towards the target, separate, stop (3 s)."""
        self.drive(90, "RIDING")
        self.drive(90, "NAVIGATING")
        assert self.modes[-1] is CarrierMode.SEPARATED and not self.v[-1].any()


def _flight(cfg: Config, script) -> Run:  # type: ignore[no-untyped-def]
    clock = ManualClock()
    with sessions(1) as (sa, sb), CarrierSim(cfg, clock, sa) as sim:
        passenger = Passenger(sb, "p3", clock)
        try:
            wait_for(lambda: passenger.pub.matched)
            run = Run(sim, clock, passenger)
            run.deploy()
            script(run)
        finally:
            passenger.pub.close()
    return run


def _heading(v: np.ndarray) -> float:
    return math.degrees(math.atan2(float(v[1]), float(v[0])))


def test_the_carrier_drives_its_recovery_course_then_parks_for_good_then_rides_again() -> None:
    """Default heading: away from the target (from where it stood when the recovery began), at
    carrier.recovery_speed_m_s, reached and left at the acceleration limit (no jump); parked on
    HOME, and HOLD or DONE never unpark it; RIDING (the next target) drives it again."""
    def script(run: Run) -> None:
        start = run.x[-1]
        run.drive(10, "RETURNING")
        run.drive(150, "APPROACH")  # 5 s, go-around phases included: one course
        run.drive(30, "GO_AROUND")
        run.drive(60, "DOCKED")
        assert all(m is CarrierMode.RECOVERING for m in run.modes[180:])
        away = start - TARGET[:2]
        for v in run.v[-120:]:  # steady: 1.5 m/s straight away from the target
            assert v == pytest.approx(1.5 * away / np.linalg.norm(away), abs=1e-9)
        run.drive(120, "HOME")
        assert run.modes[-1] is CarrierMode.PARKED and not run.v[-1].any()
        run.drive(60, "HOLD")
        run.drive(60, "DONE")
        assert run.modes[-1] is CarrierMode.PARKED and not run.v[-1].any()
        run.drive(30, "RIDING")
        assert run.modes[-1] is CarrierMode.APPROACHING and run.v[-1].any()

    run = _flight(_cfg(recovery_speed_m_s=1.5), script)
    v = np.array(run.v)
    jumps = np.linalg.norm(np.diff(v, axis=0), axis=1)
    assert jumps.max() <= ACCEL * DT + 1e-9  # every switch of mode, at the acceleration limit
    parked = [i for i, m in enumerate(run.modes) if m is CarrierMode.PARKED]
    assert not v[parked[0] + 60:parked[-1] + 1].any()  # stopped within 1.5 s and stayed
    assert min(run.distances) >= RADIUS - 1e-9


def test_a_scripted_turn_and_a_course_at_the_target_keep_p3() -> None:
    """carrier.recovery_course: 2 s straight at the target at 2 m/s, then 90 deg to the side;
    the steady course then points at the target again. The turn is flown at the acceleration
    limit; the guard stops the carrier at b c - margin, whatever the course says."""
    towards = _heading(TARGET[:2])  # the carrier stands on the line from the origin to the target
    cfg = _cfg(recovery_speed_m_s=2.0, recovery_heading_deg=towards,
               recovery_course=[[towards, 2.0, 2.0], [towards + 90.0, 2.0, 3.0]])

    def script(run: Run) -> None:
        run.drive(60 + 90 + 240, "HOLDOFF")

    run = _flight(cfg, script)
    v = np.array(run.v[180:])
    assert np.linalg.norm(np.diff(v, axis=0), axis=1).max() <= ACCEL * DT + 1e-9
    assert _heading(v[59]) == pytest.approx(towards, abs=0.5)  # 2 s into the recovery: the first leg
    assert _heading(v[147]) == pytest.approx(towards + 90.0, abs=0.5)  # turned (2.8 s at the limit) by 2.9 s
    assert 0.5 < np.linalg.norm(v[60 + 30]) < 2.0  # mid-turn: the acceleration limit cuts the corner
    assert min(run.distances) >= RADIUS - 1e-9
    assert min(run.distances) < RADIUS + 0.5  # the steady course drove it to the guard's circle
    assert run.sim.summary()["guard_active_ticks"] > 0


def test_a_passenger_lost_during_the_recovery_stops_the_carrier_until_it_is_heard_again() -> None:
    def script(run: Run) -> None:
        run.drive(90, "APPROACH")
        assert run.modes[-1] is CarrierMode.RECOVERING and np.linalg.norm(run.v[-1]) == pytest.approx(1.0)
        run.drive(90, None)  # silent for 3 s (> carrier.passenger_timeout_s = 1 s)
        assert run.modes[-1] is CarrierMode.PAUSED and not run.v[-1].any()
        run.drive(60, "APPROACH")
        assert run.modes[-1] is CarrierMode.RECOVERING and np.linalg.norm(run.v[-1]) == pytest.approx(1.0)

    run = _flight(_cfg(recovery_speed_m_s=1.0), script)
    assert CarrierMode.PAUSED in run.modes
