"""Ackermann rover kinematics of the mock vehicle's rover frame (``--frame rover``; pure).

What PX4's Ackermann rover does with an OFFBOARD velocity setpoint (``AckermannOffboardMode.cpp``,
``AckermannVelControl.cpp``): the setpoint becomes a speed ``|v_sp|`` (horizontal norm) and a
bearing ``atan2(v_e, v_n)``; the speed loop slews towards the speed with RO_ACCEL_LIM /
RO_DECEL_LIM, and the attitude loop steers the heading to the bearing. The model here::

    speed:  towards min(|v_sp|, speed_max) at most accel_m_s2 up, decel_m_s2 down    (forward only)
    yaw:    psi' = sat(yaw_gain wrap(bearing - psi), |speed| tan(max_steer) / wheelbase)
    motion: n' = speed cos psi, e' = speed sin psi; d stays on the ground

so a rover, unlike a multicopter, cannot move sideways, needs speed to turn, and brakes over
``v^2 / (2 decel)``. As in PX4, a zero setpoint has bearing ``atan2(0, 0) = 0``: a rover told to
stop steers north while it brakes. Outside OFFBOARD (Hold, failsafes) it brakes to a stop
holding its heading, as PX4 rovers hold.
Wind and the vertical command are ignored (a ground vehicle).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from mission.core.geodesy import wrap_pi
from sim.vehicle.physics.multicopter import Command, KinState

STOP = Command(0.0, 0.0, 0.0)


@dataclass(frozen=True)
class RoverLimits:
    """speed_max_m_s [m/s]; accel_m_s2 / decel_m_s2 [m/s^2] of the speed slew; yaw_gain [1/s];
    wheelbase_m [m]; max_steer_rad [rad]. Defaults: PX4's SIH Ackermann rover (airframe 10045:
    RO_SPEED_LIM, RO_ACCEL_LIM, RO_DECEL_LIM, RO_YAW_P, RA_WHEEL_BASE, RA_MAX_STR_ANG)."""

    speed_max_m_s: float = 3.0
    accel_m_s2: float = 3.0
    decel_m_s2: float = 3.0
    yaw_gain: float = 5.0
    wheelbase_m: float = 0.321
    max_steer_rad: float = 0.5236


def rover_step(state: KinState, command: Command, limits: RoverLimits, dt_s: float, steer: bool = True) -> KinState:
    """Advance the rover by ``dt_s`` [s] under ``command`` (its horizontal velocity; see the module
    docstring); ``steer`` False holds the heading (a mode other than OFFBOARD)."""
    speed = math.hypot(state.vn_m_s, state.ve_m_s)
    speed_sp = min(math.hypot(command.vn_m_s, command.ve_m_s), limits.speed_max_m_s) if command.powered else 0.0
    if speed_sp > speed:
        new_speed = min(speed_sp, speed + limits.accel_m_s2 * dt_s)
    else:
        new_speed = max(speed_sp, speed - limits.decel_m_s2 * dt_s)
    yaw = state.yaw_rad
    if steer and command.powered:
        bearing = math.atan2(command.ve_m_s, command.vn_m_s)  # 0 (north) for a zero setpoint, as in PX4
        rate_max = new_speed * math.tan(limits.max_steer_rad) / limits.wheelbase_m
        rate = min(max(limits.yaw_gain * wrap_pi(bearing - yaw), -rate_max), rate_max)
    else:
        rate = 0.0
    mid = yaw + 0.5 * rate * dt_s
    mean_speed = 0.5 * (speed + new_speed)
    n = state.n_m + mean_speed * math.cos(mid) * dt_s
    e = state.e_m + mean_speed * math.sin(mid) * dt_s
    yaw = wrap_pi(yaw + rate * dt_s)
    vn, ve = new_speed * math.cos(yaw), new_speed * math.sin(yaw)
    return KinState(n, e, state.d_m, vn, ve, 0.0, yaw, rate, (vn - state.vn_m_s) / dt_s, (ve - state.ve_m_s) / dt_s,
                    state.ground_d_m, True)


def rover_stepper(mode_of: Callable[[], str], limits: RoverLimits | None = None) -> Callable[..., KinState]:
    """A step function with the signature of :func:`sim.vehicle.physics.multicopter.step` for the mock vehicle:
    the command is obeyed in OFFBOARD (``mode_of()``), any other mode brakes to a stop."""
    lim = limits or RoverLimits()

    def step(state: KinState, command: Command, _limits: object, _wind: object, dt_s: float) -> KinState:
        # a setpoint without a finite horizontal velocity (PX4 semantics: NaN = not controlled) stops it
        offboard = mode_of() == "OFFBOARD"
        drive = offboard and math.isfinite(command.vn_m_s) and math.isfinite(command.ve_m_s)
        return rover_step(state, command if drive else STOP, lim, dt_s, steer=drive)

    return step
