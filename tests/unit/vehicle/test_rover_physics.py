"""The mock vehicle's rover frame: PX4's Ackermann offboard rules as kinematics (pure)."""
from __future__ import annotations

import math

import pytest

from sim.vehicle.physics.rover import RoverLimits, rover_step, rover_stepper
from sim.vehicle.physics.multicopter import Command, KinState

DT = 0.005
LIM = RoverLimits(speed_max_m_s=3.0, accel_m_s2=1.0, decel_m_s2=1.5, yaw_gain=2.0, wheelbase_m=0.32, max_steer_rad=0.5)


def _run(state: KinState, command: Command, seconds: float) -> KinState:
    for _ in range(int(round(seconds / DT))):
        state = rover_step(state, command, LIM, DT)
    return state


def test_accelerates_at_the_limit_and_brakes_over_v2_over_2a() -> None:
    s = _run(KinState(0.0, 0.0, 0.0), Command(2.0, 0.0, 0.0), 2.0)  # 1 m/s^2 for 2 s
    assert math.hypot(s.vn_m_s, s.ve_m_s) == pytest.approx(2.0, abs=1e-9)
    assert s.n_m == pytest.approx(2.0, abs=1e-2)  # a t^2 / 2
    n0 = s.n_m
    s = _run(s, Command(0.0, 0.0, 0.0), 3.0)
    assert math.hypot(s.vn_m_s, s.ve_m_s) == 0.0
    assert s.n_m - n0 == pytest.approx(2.0 ** 2 / (2 * 1.5), abs=1e-2)


def test_cannot_move_sideways_or_turn_standing_still() -> None:
    s = _run(KinState(0.0, 0.0, 0.0), Command(0.0, 0.0, 0.0), 1.0)
    s = rover_step(s, Command(0.0, 1.0, 0.0), LIM, DT)  # east, from standing still facing north
    assert s.vn_m_s > 0 and abs(s.ve_m_s) < 1e-3 * s.vn_m_s and s.yaw_rad < 1e-2  # it sets off forward (north)
    s = _run(s, Command(0.0, 1.0, 0.0), 4.0)
    assert s.yaw_rad == pytest.approx(math.pi / 2, abs=1e-2)  # turned east while moving
    assert s.n_m > 0.0  # along an arc: some of the motion went north first
    assert s.d_m == 0.0 and s.vd_m_s == 0.0  # on the ground


def test_outside_offboard_it_brakes_to_a_stop() -> None:
    mode = ["OFFBOARD"]
    step = rover_stepper(lambda: mode[0], LIM)
    s = KinState(0.0, 0.0, 0.0)
    for _ in range(400):
        s = step(s, Command(2.0, 0.0, 0.0), None, None, DT)
    assert s.vn_m_s > 1.9
    mode[0] = "AUTO.LOITER"
    for _ in range(400):
        s = step(s, Command(2.0, 0.0, 0.0), None, None, DT)
    assert s.vn_m_s == 0.0
