"""PX4's position controller as the mock runs it, and the airframe it flies (pure functions)."""
from __future__ import annotations

import math

import pytest

from sim.vehicle.physics.mc_position_control import GRAVITY_M_S2, ControllerState, Gains, Setpoint3, constrain_xy, control, velocity_setpoint
from sim.vehicle.physics.multicopter import Command, KinState, Limits, initial_state, step

NAN = math.nan
ZERO = (0.0, 0.0, 0.0)


def fly(command: Command, seconds: float, kin: KinState | None = None, wind=ZERO, dt_s: float = 0.005) -> KinState:
    kin = kin or KinState(0.0, 0.0, -10.0, ground_d_m=0.0, on_ground=False)
    for _ in range(round(seconds / dt_s)):
        kin = step(kin, command, Limits(), wind, dt_s)
    return kin


def test_position_part_has_priority_over_the_feed_forward():
    assert constrain_xy((3.0, 0.0), (0.0, 4.0), 12.0) == (3.0, 4.0)
    n, e = constrain_xy((3.0, 0.0), (0.0, 10.0), 5.0)
    assert math.hypot(n, e) == pytest.approx(5.0) and n == pytest.approx(3.0)
    assert constrain_xy((20.0, 0.0), (0.0, 10.0), 5.0) == pytest.approx((5.0, 0.0))


def test_position_only_is_a_p_loop_with_mpc_xy_p_and_the_speed_limit():
    gains = Gains()
    vel = velocity_setpoint(Setpoint3(position=(1.0, -2.0, -5.0)), (0.0, 0.0, -4.0), gains)
    assert vel == pytest.approx((0.95, -1.9, -1.0))  # MPC_XY_P 0.95, MPC_Z_P 1
    far = velocity_setpoint(Setpoint3(position=(100.0, 0.0, -100.0)), ZERO, gains)
    assert far == pytest.approx((12.0, 0.0, -3.0))  # MPC_XY_VEL_MAX, MPC_Z_VEL_MAX_UP
    with_ff = velocity_setpoint(Setpoint3(position=(1.0, 0.0, 0.0), velocity=(2.0, 0.0, 0.0)), ZERO, gains)
    assert with_ff == pytest.approx((2.95, 0.0, 0.0))


def test_tilt_limit_caps_the_horizontal_acceleration():
    sp = Setpoint3(velocity=(NAN, NAN, 0.0), acceleration=(50.0, 0.0, NAN))  # acceleration only, horizontally
    produced, _ = control(sp, ZERO, ZERO, ZERO, ControllerState(), Gains(), 0.005)
    assert produced[0] == pytest.approx(GRAVITY_M_S2 * math.tan(math.radians(45.0)), rel=1e-6)  # MPC_TILTMAX_AIR
    assert produced[2] == pytest.approx(0.0, abs=1e-9)  # altitude kept
    small, _ = control(Setpoint3(velocity=(NAN, NAN, 0.0), acceleration=(1.0, -0.5, NAN)), ZERO, ZERO, ZERO,
                       ControllerState(), Gains(), 0.005)
    assert small[:2] == pytest.approx((1.0, -0.5))


def test_invalid_setpoint_stops_as_px4_failsafe():
    assert not Setpoint3(position=(1.0, NAN, NAN), velocity=(NAN, NAN, 0.0)).valid()  # x without y
    assert not Setpoint3(velocity=(1.0, 0.0, NAN)).valid()  # nothing for z
    kin = fly(Command(2.0, 0.0, 0.0), 5.0)
    stopped = fly(Command(NAN, 0.0, 0.0), 6.0, kin)
    assert stopped == fly(Command(0.0, 0.0, 0.0), 6.0, kin)  # "stop and wait": zero velocity
    assert math.hypot(stopped.vn_m_s, stopped.ve_m_s) < 0.2  # (PX4's integrator leaves a slow residual)


def test_horizontal_step_has_px4s_drag_deficit_then_the_integrator_closes_it():
    after_4s = fly(Command(2.0, 0.0, 0.0), 4.0)
    assert 0.75 < after_4s.vn_m_s / 2.0 < 0.85  # PX4 SITL: 79-84 % in 4 s
    after_40s = fly(Command(2.0, 0.0, 0.0), 36.0, after_4s)
    assert after_40s.vn_m_s == pytest.approx(2.0, rel=0.01)
    assert after_40s.ctrl.integral[0] == pytest.approx(Limits().airframe.drag_1_s * 2.0, rel=0.02)


def test_wind_is_a_force_the_integrator_compensates():
    wind = (0.0, 2.0, 0.0)
    early = fly(Command(0.0, 0.0, 0.0), 1.0, wind=wind)
    assert early.ve_m_s > 0.2  # blown downwind at first
    late = fly(Command(0.0, 0.0, 0.0), 40.0, early, wind=wind)
    assert abs(late.ve_m_s) < 0.05
    held = fly(Command(NAN, NAN, NAN, position_ned_m=(0.0, 0.0, -10.0)), 40.0, wind=wind)
    assert math.hypot(held.n_m, held.e_m) < 0.1


def test_on_the_ground_it_waits_for_a_climb_request():
    kin = initial_state((1.0, 2.0, 0.0))
    assert fly(Command(1.0, 1.0, 0.0), 1.0, kin) == kin  # no sliding, no liftoff without climbing
    assert fly(Command(NAN, NAN, NAN, position_ned_m=(1.0, 2.0, 0.5)), 1.0, kin) == kin  # below ground
    up = fly(Command(NAN, NAN, NAN, position_ned_m=(1.0, 2.0, -2.0)), 5.0, kin)
    assert not up.on_ground and up.d_m == pytest.approx(-2.0, abs=0.1)
    assert fly(Command(0.0, 0.0, 0.0, powered=False), 5.0, up).on_ground


def test_landed_it_takes_off_when_the_setpoint_is_above_its_estimate_not_the_truth():
    """PX4's offboard ``want_takeoff`` compares the setpoint with the estimated height
    (``states.position(2)``): landed at d = -0.5 with the estimate reading 0.3 m lower (d -0.2), a
    position setpoint at d -0.4 (above the estimate, below the truth) lifts it off, one at d -0.1
    does not; with the estimate reading 0.3 m higher a setpoint at d -0.6 does not."""
    nan = math.nan
    landed = initial_state((0.0, 0.0, -0.5))
    zero = (0.0, 0.0, 0.0)

    def lifts(sp_d: float, est_d: float) -> bool:
        command = Command(nan, nan, 0.0, position_ned_m=(0.0, 0.0, sp_d), acceleration_ned_m_s2=(nan, nan, nan))
        after = step(landed, command, Limits(), zero, 0.004, ((0.0, 0.0, est_d), zero))
        return not after.on_ground or after.vd_m_s < 0.0

    assert lifts(-0.4, 0.3) and not lifts(-0.1, 0.3) and not lifts(-0.6, -0.3) and lifts(-0.9, -0.3)
