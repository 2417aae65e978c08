"""Point-mass multicopter kinematics of the mock vehicle (pure functions, no I/O).

Frames and units: local NED [m] around the EKF origin (home), velocities [m/s] NED, yaw [rad]
from north, clockwise positive. ``d <= ground_d_m`` is above the ground; the vehicle can never be
below it.

Model, per fixed step ``dt_s``:
- the commanded velocity is clamped to the speed limits (horizontal norm ``xy_vel_max_m_s``,
  climb ``z_vel_max_up_m_s``, descent ``z_vel_max_dn_m_s``);
- the velocity follows it with a first-order response of time constant ``tau_s`` (exact
  discretisation: after one step the remaining error is ``exp(-dt/tau)`` of the previous one),
  with the change per step limited by the horizontal acceleration ``acc_hor_m_s2`` (norm) and
  the vertical ``acc_up_m_s2`` / ``acc_dn_m_s2``;
- in the air the ground velocity is that response plus the wind (an uncompensated drift: the
  modes with a position loop correct it, a pure velocity setpoint does not);
- on the ground the vehicle does not slide: it stays put until it is powered and commanded
  upwards (``vd < 0``), then it lifts off at once; touching the ground while descending stops it;
- unpowered (disarmed) in the air it falls freely.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

GRAVITY_M_S2 = 9.80665
YAW_TIME_CONSTANT_S = 0.3
TOUCHDOWN_SPEED_M_S = 0.05  # below this climb rate on the ground it is not a liftoff


@dataclass(frozen=True)
class Limits:
    """Velocity and acceleration limits [m/s, m/s^2], response time constant [s], yaw rate [rad/s]."""

    xy_vel_max_m_s: float = 12.0
    z_vel_max_up_m_s: float = 3.0
    z_vel_max_dn_m_s: float = 1.5
    acc_hor_m_s2: float = 3.0
    acc_up_m_s2: float = 4.0
    acc_dn_m_s2: float = 3.0
    tau_s: float = 0.2
    yaw_rate_max_rad_s: float = math.radians(45.0)


@dataclass(frozen=True, slots=True)
class Command:
    """What the flight controller asks of the point mass: velocity [m/s] NED and a yaw target.

    ``yaw_rad`` (absolute) takes precedence over ``yaw_rate_rad_s``; with neither, yaw is held.
    ``powered`` is False when disarmed (motors off).
    """

    vn_m_s: float = 0.0
    ve_m_s: float = 0.0
    vd_m_s: float = 0.0
    yaw_rad: float | None = None
    yaw_rate_rad_s: float | None = None
    powered: bool = True


@dataclass(frozen=True, slots=True)
class KinState:
    """Point-mass state: position [m] NED, velocity [m/s] NED (without wind), yaw [rad].

    ``an_m_s2, ae_m_s2`` is the last horizontal acceleration (for the attitude telemetry),
    ``yaw_rate_rad_s`` the last yaw rate. ``ground_d_m`` is the level the vehicle stands on
    (the carrier deck at start, the ground ``0`` once it has lifted off). ``on_ground`` is the
    landed flag of the physics (no motion possible but liftoff).
    """

    n_m: float
    e_m: float
    d_m: float
    vn_m_s: float = 0.0
    ve_m_s: float = 0.0
    vd_m_s: float = 0.0
    yaw_rad: float = 0.0
    yaw_rate_rad_s: float = 0.0
    an_m_s2: float = 0.0
    ae_m_s2: float = 0.0
    ground_d_m: float = 0.0
    on_ground: bool = True


def initial_state(start_ned_m: tuple[float, float, float]) -> KinState:
    """State at start. ``d >= 0``: on the ground (d = 0); ``d < 0``: standing on a platform
    (the carrier deck) at that height, which supports it until it first lifts off."""
    n, e, d = (float(x) for x in start_ned_m)
    ground = min(d, 0.0)
    return KinState(n_m=n, e_m=e, d_m=ground, ground_d_m=ground, on_ground=True)


def clamp_velocity(vn: float, ve: float, vd: float, limits: Limits) -> tuple[float, float, float]:
    """Commanded velocity [m/s] NED clamped to the horizontal norm and vertical limits."""
    speed_h = math.hypot(vn, ve)
    if speed_h > limits.xy_vel_max_m_s > 0.0:
        scale = limits.xy_vel_max_m_s / speed_h
        vn, ve = vn * scale, ve * scale
    vd = min(max(vd, -limits.z_vel_max_up_m_s), limits.z_vel_max_dn_m_s)
    return vn, ve, vd


def wrap_pi(angle_rad: float) -> float:
    """Angle wrapped to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def _yaw_rate(state: KinState, command: Command, limits: Limits) -> float:
    if command.yaw_rad is not None:
        rate = wrap_pi(command.yaw_rad - state.yaw_rad) / YAW_TIME_CONSTANT_S
    elif command.yaw_rate_rad_s is not None:
        rate = command.yaw_rate_rad_s
    else:
        rate = 0.0
    return min(max(rate, -limits.yaw_rate_max_rad_s), limits.yaw_rate_max_rad_s)


def _response(state: KinState, command: Command, limits: Limits, dt_s: float) -> tuple[float, float, float, float, float]:
    """New velocity (vn, ve, vd) [m/s] and horizontal acceleration (an, ae) [m/s^2]."""
    vn_c, ve_c, vd_c = clamp_velocity(command.vn_m_s, command.ve_m_s, command.vd_m_s, limits)
    alpha = 1.0 - math.exp(-dt_s / limits.tau_s) if limits.tau_s > 0 else 1.0
    dvn, dve, dvd = (vn_c - state.vn_m_s) * alpha, (ve_c - state.ve_m_s) * alpha, (vd_c - state.vd_m_s) * alpha
    dv_h_max = limits.acc_hor_m_s2 * dt_s
    dv_h = math.hypot(dvn, dve)
    if dv_h > dv_h_max:
        scale = dv_h_max / dv_h
        dvn, dve = dvn * scale, dve * scale
    dvd = min(max(dvd, -limits.acc_up_m_s2 * dt_s), limits.acc_dn_m_s2 * dt_s)
    return state.vn_m_s + dvn, state.ve_m_s + dve, state.vd_m_s + dvd, dvn / dt_s, dve / dt_s


def step(state: KinState, command: Command, limits: Limits, wind_ned_m_s: tuple[float, float, float], dt_s: float) -> KinState:
    """Advance the point mass by ``dt_s`` [s] under ``command``; see the module docstring."""
    if state.on_ground and not (command.powered and command.vd_m_s < -TOUCHDOWN_SPEED_M_S):
        return state  # landed states are always at rest on their ground
    yaw_rate = _yaw_rate(state, command, limits) if command.powered else 0.0
    if command.powered:
        vn, ve, vd, an, ae = _response(state, command, limits, dt_s)
    else:
        vn, ve, vd, an, ae = state.vn_m_s, state.ve_m_s, state.vd_m_s + GRAVITY_M_S2 * dt_s, 0.0, 0.0
    wn, we, wd = wind_ned_m_s
    n = state.n_m + (vn + wn) * dt_s
    e = state.e_m + (ve + we) * dt_s
    d = state.d_m + (vd + wd) * dt_s
    yaw = wrap_pi(state.yaw_rad + yaw_rate * dt_s)
    # once it lifts off, the platform it stood on (the carrier deck) no longer supports it
    ground = 0.0 if state.on_ground else state.ground_d_m
    if d >= ground and not state.on_ground:
        return KinState(n, e, ground, yaw_rad=yaw, ground_d_m=ground, on_ground=True)
    return KinState(n, e, d, vn, ve, vd, yaw, yaw_rate, an, ae, ground, False)


def attitude_rad(state: KinState) -> tuple[float, float, float]:
    """(roll, pitch, yaw) [rad] a multicopter would show for the horizontal acceleration."""
    cos_y, sin_y = math.cos(state.yaw_rad), math.sin(state.yaw_rad)
    a_fwd = cos_y * state.an_m_s2 + sin_y * state.ae_m_s2
    a_right = -sin_y * state.an_m_s2 + cos_y * state.ae_m_s2
    return math.atan2(a_right, GRAVITY_M_S2), -math.atan2(a_fwd, GRAVITY_M_S2), state.yaw_rad


def quaternion(roll_rad: float, pitch_rad: float, yaw_rad: float) -> tuple[float, float, float, float]:
    """Hamilton quaternion (w, x, y, z) of the ZYX Euler angles, body FRD to NED."""
    cr, sr = math.cos(roll_rad / 2), math.sin(roll_rad / 2)
    cp, sp = math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return (cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy)


def body_to_ned(v_fwd: float, v_right: float, vd: float, yaw_rad: float) -> tuple[float, float, float]:
    """Rotate a BODY_NED velocity [m/s] by yaw only (as PX4 does for MAV_FRAME_BODY_NED)."""
    cos_y, sin_y = math.cos(yaw_rad), math.sin(yaw_rad)
    return cos_y * v_fwd - sin_y * v_right, sin_y * v_fwd + cos_y * v_right, vd
