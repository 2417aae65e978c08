"""Multicopter dynamics of the mock vehicle: PX4's position controller on an SIH-like airframe.

Pure functions, no I/O. Frames and units: local NED [m] around the EKF origin (home), velocities
[m/s] NED, yaw [rad] from north, clockwise positive. ``d <= ground_d_m`` is above the ground; the
vehicle can never be below it.

Model, per fixed step ``dt_s`` (structured as PX4 SITL with its SIH simulator):
- the command is a trajectory setpoint (position, velocity, acceleration; NaN = not controlled),
  flown by PX4's position controller (:mod:`sim.vehicle.physics.mc_position_control`, the ``MPC_*`` gains): it
  yields the acceleration the thrust setpoint asks for;
- the airframe realises that acceleration through a first-order lag (attitude loop and motors;
  :class:`Airframe` ``tilt_tau_s`` horizontally, ``thrust_tau_s`` vertically) and feels SIH's
  linear drag ``-drag_1_s * (v - wind)`` (``SIH_KDV / SIH_MASS``; vertically ``drag_z_1_s``, what
  PX4's hover-thrust estimator leaves of it). The wind is therefore a force
  that PX4's velocity integrator slowly compensates, as on SIH;
- the constants of :data:`FITTED_AIRFRAME` are fitted to a real PX4 SITL's recorded responses
  (``bench/px4_response_fit.py``);
- on the ground the vehicle does not slide: it stays put until it is powered and the setpoint
  asks to climb (PX4's ``want_takeoff``), then it lifts off at once; touching the ground while
  descending stops it (the controller's integrator resets on the ground, as PX4's does);
- unpowered (disarmed) in the air it falls, with drag.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from mission.core.geodesy import wrap_pi
from sim.vehicle.physics.mc_position_control import GRAVITY_M_S2, ControllerState, Gains, Setpoint3, Vec3, control_at_rate

YAW_TIME_CONSTANT_S = 0.3
NAN = math.nan


@dataclass(frozen=True)
class Airframe:
    """The free constants of the airframe [s, 1/s]: what PX4's parameters do not fix."""

    drag_1_s: float = 1.0  # SIH_KDV / SIH_MASS: linear drag per unit mass, horizontal [1/s]
    tilt_tau_s: float = 0.25  # lag of the horizontal acceleration behind the controller's [s]
    thrust_tau_s: float = 0.08  # lag of the vertical acceleration [s]
    # vertical drag as the controller feels it [1/s]: PX4's hover-thrust estimator (MPC_USE_HTE)
    # takes part of SIH's vertical drag for a change of hover thrust and compensates it
    drag_z_1_s: float = 1.0


# fitted to ../shared/px4_sitl/responses (original recording) by ``python -m bench.px4_response_fit --fit``
FITTED_AIRFRAME = Airframe(drag_1_s=1.099, tilt_tau_s=0.2816, thrust_tau_s=0.0568, drag_z_1_s=0.699)


@dataclass(frozen=True)
class Limits:
    """Everything that shapes the response: PX4's controller gains and limits, the airframe,
    and the yaw rate limit [rad/s] (``MPC_YAWRAUTO_MAX``)."""

    gains: Gains = field(default_factory=Gains)
    airframe: Airframe = FITTED_AIRFRAME
    yaw_rate_max_rad_s: float = math.radians(45.0)


@dataclass(frozen=True, slots=True)
class Command:
    """What the flight controller asks of the vehicle: a trajectory setpoint and a yaw target.

    Velocity [m/s] NED (``vn_m_s, ve_m_s, vd_m_s``), position [m] NED (``position_ned_m``) and
    acceleration feed-forward [m/s^2] NED (``acceleration_ned_m_s2``); a NaN component is not
    controlled (PX4 semantics). ``yaw_rad`` (absolute) takes precedence over
    ``yaw_rate_rad_s``; with neither, yaw is held. ``powered`` is False when disarmed.
    """

    vn_m_s: float = 0.0
    ve_m_s: float = 0.0
    vd_m_s: float = 0.0
    yaw_rad: float | None = None
    yaw_rate_rad_s: float | None = None
    powered: bool = True
    position_ned_m: tuple[float, float, float] = (NAN, NAN, NAN)
    acceleration_ned_m_s2: tuple[float, float, float] = (NAN, NAN, NAN)

    def setpoint(self) -> Setpoint3:
        return Setpoint3(self.position_ned_m, (self.vn_m_s, self.ve_m_s, self.vd_m_s), self.acceleration_ned_m_s2)


@dataclass(frozen=True, slots=True)
class KinState:
    """Vehicle state: position [m] NED, velocity [m/s] NED (over ground), yaw [rad].

    ``an_m_s2, ae_m_s2, ad_m_s2`` is the acceleration the thrust produces (gravity compensated:
    hover is 0; it sets the attitude telemetry), ``dvn, dve, dvd`` the low-passed acceleration
    PX4's D term sees, ``ctrl`` the position controller's memory, ``yaw_rate_rad_s`` the last
    yaw rate. ``ground_d_m`` is the level the vehicle stands on (the carrier deck at start, the
    ground ``0`` once it has lifted off). ``on_ground`` is the landed flag of the physics.
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
    ad_m_s2: float = 0.0
    dvn_m_s2: float = 0.0
    dve_m_s2: float = 0.0
    dvd_m_s2: float = 0.0
    ctrl: ControllerState = ControllerState()


def initial_state(start_ned_m: tuple[float, float, float]) -> KinState:
    """State at start. ``d >= 0``: on the ground (d = 0); ``d < 0``: standing on a platform
    (the carrier deck) at that height, which supports it until it first lifts off."""
    n, e, d = (float(x) for x in start_ned_m)
    ground = min(d, 0.0)
    return KinState(n_m=n, e_m=e, d_m=ground, ground_d_m=ground, on_ground=True)


def _yaw_rate(state: KinState, command: Command, limits: Limits) -> float:
    if command.yaw_rad is not None:
        rate = wrap_pi(command.yaw_rad - state.yaw_rad) / YAW_TIME_CONSTANT_S
    elif command.yaw_rate_rad_s is not None:
        rate = command.yaw_rate_rad_s
    else:
        rate = 0.0
    return min(max(rate, -limits.yaw_rate_max_rad_s), limits.yaw_rate_max_rad_s)


def _lag(value: float, target: float, dt_s: float, tau_s: float) -> float:
    """One exact step of a first-order lag of time constant ``tau_s`` towards ``target``."""
    return target if tau_s <= 0.0 else target + (value - target) * math.exp(-dt_s / tau_s)


def step(state: KinState, command: Command, limits: Limits, wind_ned_m_s: tuple[float, float, float], dt_s: float,
         estimate_error: tuple[Vec3, Vec3] | None = None) -> KinState:
    """Advance the vehicle by ``dt_s`` [s] under ``command``; see the module docstring.
    ``estimate_error``: (position [m], velocity [m/s]) NED that PX4's estimate adds to the true
    state; the position controller flies the estimate (:mod:`sim.vehicle.estimator`)."""
    sp = command.setpoint()
    seen_d = state.d_m + (estimate_error[0][2] if estimate_error is not None else 0.0)  # PX4 reads its estimate
    if state.on_ground and not (command.powered and sp.wants_climb(seen_d)):
        # landed: at rest on its ground, the controller's integrator reset (as PX4's)
        if state.ctrl.integral == (0.0, 0.0, 0.0) and state.an_m_s2 == state.ae_m_s2 == state.ad_m_s2 == 0.0:
            return state
        return KinState(state.n_m, state.e_m, state.d_m, yaw_rad=state.yaw_rad, ground_d_m=state.ground_d_m, on_ground=True)
    air = limits.airframe
    pos = (state.n_m, state.e_m, state.d_m)
    vel = (state.vn_m_s, state.ve_m_s, state.vd_m_s)
    if command.powered:
        yaw_rate = _yaw_rate(state, command, limits)
        seen_pos, seen_vel = pos, vel
        if estimate_error is not None:
            (ep, ev) = estimate_error
            seen_pos = (pos[0] + ep[0], pos[1] + ep[1], pos[2] + ep[2])
            seen_vel = (vel[0] + ev[0], vel[1] + ev[1], vel[2] + ev[2])
        acc_sp, ctrl = control_at_rate(sp, seen_pos, seen_vel, (state.dvn_m_s2, state.dve_m_s2, state.dvd_m_s2), state.ctrl,
                                       limits.gains, dt_s)
        an = _lag(state.an_m_s2, acc_sp[0], dt_s, air.tilt_tau_s)
        ae = _lag(state.ae_m_s2, acc_sp[1], dt_s, air.tilt_tau_s)
        ad = _lag(state.ad_m_s2, acc_sp[2], dt_s, air.thrust_tau_s)
    else:
        yaw_rate, ctrl = 0.0, ControllerState()
        an, ae, ad = 0.0, 0.0, GRAVITY_M_S2
    wn, we, wd = wind_ned_m_s
    k = air.drag_1_s
    accel = (an - k * (vel[0] - wn), ae - k * (vel[1] - we), ad - air.drag_z_1_s * (vel[2] - wd))
    vn, ve, vd = (vel[i] + accel[i] * dt_s for i in range(3))
    n, e, d = state.n_m + vn * dt_s, state.e_m + ve * dt_s, state.d_m + vd * dt_s
    alpha = 1.0 - math.exp(-dt_s * 2.0 * math.pi * limits.gains.veld_lp_hz)
    dvn = state.dvn_m_s2 + (accel[0] - state.dvn_m_s2) * alpha
    dve = state.dve_m_s2 + (accel[1] - state.dve_m_s2) * alpha
    dvd = state.dvd_m_s2 + (accel[2] - state.dvd_m_s2) * alpha
    yaw = wrap_pi(state.yaw_rad + yaw_rate * dt_s)
    # once it lifts off, the platform it stood on (the carrier deck) no longer supports it
    ground = 0.0 if state.on_ground else state.ground_d_m
    if d >= ground and not state.on_ground:
        return KinState(n, e, ground, yaw_rad=yaw, ground_d_m=ground, on_ground=True)
    return KinState(n, e, d, vn, ve, vd, yaw, yaw_rate, an, ae, ground, False, ad, dvn, dve, dvd, ctrl)


def attitude_rad(state: KinState) -> tuple[float, float, float]:
    """(roll, pitch, yaw) [rad] a multicopter would show for the horizontal acceleration."""
    cos_y, sin_y = math.cos(state.yaw_rad), math.sin(state.yaw_rad)
    a_fwd = cos_y * state.an_m_s2 + sin_y * state.ae_m_s2
    a_right = -sin_y * state.an_m_s2 + cos_y * state.ae_m_s2
    return math.atan2(a_right, GRAVITY_M_S2), -math.atan2(a_fwd, GRAVITY_M_S2), state.yaw_rad


def attitude_quaternion(state: KinState) -> tuple[float, float, float, float]:
    """(w, x, y, z), body FRD to NED: the attitude :func:`attitude_rad` gives (what a camera fixed
    to the body looks along, and what ATTITUDE_QUATERNION reports)."""
    return quaternion(*attitude_rad(state))


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
