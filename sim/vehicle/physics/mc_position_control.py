"""PX4's multicopter position controller, as the mock vehicle runs it (pure functions, no I/O).

A transcription of ``PositionControl`` in PX4's ``src/modules/mc_pos_control`` (the controller
that flies OFFBOARD setpoints: in OFFBOARD the trajectory setpoint reaches it unsmoothed):

- position P loop: ``v_sp = v_ff + MPC_XY_P * (p_sp - p)`` (``MPC_Z_P`` vertically), the
  horizontal norm limited to ``MPC_XY_VEL_MAX`` with the position part given priority over the
  feed-forward, the vertical to ``MPC_Z_VEL_MAX_UP`` / ``_DN``;
- velocity PID: ``a_sp = a_ff + P (v_sp - v) + I - D v_dot`` with the ``MPC_*_VEL_*_ACC`` gains
  (``v_dot`` the vehicle's acceleration through a ``MPC_VELD_LP`` low-pass);
- acceleration to thrust: the tilt of ``(-a_n, -a_e, g)`` limited to ``MPC_TILTMAX_AIR``, the
  collective thrust scaled by the hover thrust, vertical thrust first with a horizontal margin
  ``MPC_THR_XY_MARG``, tracking anti-windup horizontally and the thrust-limit anti-windup
  vertically.

NaN in a setpoint component means "not controlled" exactly as in PX4: a position component
without velocity feed-forward is flown by the P loop alone, a velocity without position by the
PID alone, and an acceleration without velocity is flown open loop. Frames and units: local NED
[m, m/s, m/s^2]; ``acceleration`` outputs are kinematic accelerations (hover = 0, gravity
compensated).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from mission.core.records import replace

GRAVITY_M_S2 = 9.80665
# PX4 runs the position controller at each new estimate: 125 Hz on SITL (EKF2_PREDICT_US 10 ms on
# a 250 Hz IMU: every 2nd sample); with the mock's 5 ms physics step, every 2nd step (100 Hz)
CONTROL_PERIOD_S = 0.008
NAN = math.nan
Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Gains:
    """The PX4 parameters that shape the position controller (PX4 2025 defaults)."""

    xy_p: float = 0.95  # MPC_XY_P [1/s]
    z_p: float = 1.0  # MPC_Z_P [1/s]
    xy_vel_p: float = 1.8  # MPC_XY_VEL_P_ACC [1/s]
    xy_vel_i: float = 0.4  # MPC_XY_VEL_I_ACC [1/s^2]
    xy_vel_d: float = 0.2  # MPC_XY_VEL_D_ACC [-]
    z_vel_p: float = 4.0  # MPC_Z_VEL_P_ACC [1/s]
    z_vel_i: float = 2.0  # MPC_Z_VEL_I_ACC [1/s^2]
    z_vel_d: float = 0.0  # MPC_Z_VEL_D_ACC [-]
    veld_lp_hz: float = 5.0  # MPC_VELD_LP: low-pass of the velocity derivative [Hz]
    xy_vel_max: float = 12.0  # MPC_XY_VEL_MAX [m/s]
    z_vel_max_up: float = 3.0  # MPC_Z_VEL_MAX_UP [m/s]
    z_vel_max_dn: float = 1.5  # MPC_Z_VEL_MAX_DN [m/s]
    tilt_max_rad: float = math.radians(45.0)  # MPC_TILTMAX_AIR
    hover_thrust: float = 0.5  # MPC_THR_HOVER [0..1]
    thr_min: float = 0.12  # MPC_THR_MIN
    thr_max: float = 1.0  # MPC_THR_MAX
    thr_xy_margin: float = 0.3  # MPC_THR_XY_MARG


@dataclass(frozen=True, slots=True)
class Setpoint3:
    """A trajectory setpoint in local NED; NaN components are not controlled."""

    position: Vec3 = (NAN, NAN, NAN)
    velocity: Vec3 = (NAN, NAN, NAN)
    acceleration: Vec3 = (NAN, NAN, NAN)

    def valid(self) -> bool:
        """PX4's ``_inputValid``: every axis has some setpoint, and x and y come in pairs."""
        p, v, a = self.position, self.velocity, self.acceleration
        fin = math.isfinite
        for i in (0, 1, 2):
            if not (fin(p[i]) or fin(v[i]) or fin(a[i])):
                return False
        return fin(p[0]) == fin(p[1]) and fin(v[0]) == fin(v[1]) and fin(a[0]) == fin(a[1])

    def wants_climb(self, d_m: float) -> bool:
        """PX4's ``want_takeoff`` in OFFBOARD: a position above, an upward velocity or acceleration."""
        p_d, v_d, a_d = self.position[2], self.velocity[2], self.acceleration[2]
        return (math.isfinite(p_d) and p_d < d_m) or (math.isfinite(v_d) and v_d < 0.0) or (math.isfinite(a_d) and a_d < 0.0)


@dataclass(frozen=True, slots=True)
class ControllerState:
    """The controller's memory: the velocity integrator [m/s^2] NED (``I`` of the PID), and for
    the telemetry its last velocity setpoint [m/s] and acceleration setpoint [m/s^2] NED (PX4
    streams them as POSITION_TARGET_LOCAL_NED) and normalised thrust vector (ATTITUDE_TARGET)."""

    integral: Vec3 = (0.0, 0.0, 0.0)
    velocity_sp: Vec3 = (NAN, NAN, NAN)
    acceleration_sp: Vec3 = (0.0, 0.0, 0.0)
    thrust: Vec3 = (0.0, 0.0, -0.5)
    produced: Vec3 = (0.0, 0.0, 0.0)  # the output [m/s^2] NED, held between updates
    age_s: float = 0.0  # since the last update [s]


def _add_if_finite(base: float, addition: float) -> float:
    """PX4's ``addIfNotNan``: ``addition`` only counts if finite, and replaces a NaN base."""
    if not math.isfinite(addition):
        return base
    return base + addition if math.isfinite(base) else addition


def constrain_xy(v0: tuple[float, float], v1: tuple[float, float], max_norm: float) -> tuple[float, float]:
    """PX4's ``ControlMath::constrainXY``: ``v0 + v1`` limited to ``max_norm``, ``v0`` first."""
    s_n, s_e = v0[0] + v1[0], v0[1] + v1[1]
    if math.hypot(s_n, s_e) <= max_norm:
        return s_n, s_e
    n0 = math.hypot(*v0)
    if n0 >= max_norm:
        return (v0[0] / n0 * max_norm, v0[1] / n0 * max_norm) if n0 > 0 else (0.0, 0.0)
    n1 = math.hypot(*v1)
    if n1 < 1e-3:
        return v0
    u_n, u_e = v1[0] / n1, v1[1] / n1
    m = u_n * v0[0] + u_e * v0[1]
    c = v0[0] ** 2 + v0[1] ** 2 - max_norm ** 2
    s = -m + math.sqrt(max(m * m - c, 0.0))
    return v0[0] + u_n * s, v0[1] + u_e * s


def velocity_setpoint(sp: Setpoint3, pos: Vec3, gains: Gains) -> Vec3:
    """Position P loop: the velocity setpoint [m/s] NED, limits applied (NaN: not controlled)."""
    fin = math.isfinite
    p_sp, v_ff = sp.position, sp.velocity
    from_pos = [0.0, 0.0, 0.0]  # the position loop's part (0 where the position is not controlled)
    vel = [v_ff[0], v_ff[1], v_ff[2]]
    for i, kp in ((0, gains.xy_p), (1, gains.xy_p), (2, gains.z_p)):
        if fin(p_sp[i]):
            from_pos[i] = kp * (p_sp[i] - pos[i])
            vel[i] = vel[i] + from_pos[i] if fin(vel[i]) else from_pos[i]
    vel_n, vel_e = constrain_xy((from_pos[0], from_pos[1]), (vel[0] - from_pos[0], vel[1] - from_pos[1]), gains.xy_vel_max)
    vel_d = min(max(vel[2], -gains.z_vel_max_up), gains.z_vel_max_dn) if fin(vel[2]) else NAN
    return vel_n, vel_e, vel_d


def _thrust(acc: Vec3, gains: Gains) -> list[float]:
    """PX4's ``_accelerationControl``: normalised thrust vector NED for the acceleration setpoint."""
    g, th = GRAVITY_M_S2, gains.hover_thrust
    bx, by, bz = -acc[0], -acc[1], g
    norm = math.sqrt(bx * bx + by * by + bz * bz)
    bx, by, bz = bx / norm, by / norm, bz / norm
    if bz < math.cos(gains.tilt_max_rad):  # limitTilt: rotate body_z back towards vertical
        h = math.hypot(bx, by)
        s = math.sin(gains.tilt_max_rad)
        bx, by, bz = bx / h * s, by / h * s, math.cos(gains.tilt_max_rad)
    collective = min((acc[2] * th / g - th) / bz, -gains.thr_min)
    return [bx * collective, by * collective, bz * collective]


def control(sp: Setpoint3, pos: Vec3, vel: Vec3, vel_dot: Vec3, state: ControllerState, gains: Gains,
            dt_s: float) -> tuple[Vec3, ControllerState]:
    """One controller update: (the acceleration [m/s^2] NED the thrust produces, new state).

    The returned acceleration is what the saturated thrust setpoint would produce on a vehicle
    whose hover thrust is ``gains.hover_thrust`` (gravity compensated: hover is 0).
    """
    fin = math.isfinite
    if not sp.valid():  # PX4's mc_pos_control failsafe: stop and hold altitude
        sp = Setpoint3(velocity=(0.0, 0.0, 0.0))
    vel_sp = velocity_setpoint(sp, pos, gains)
    a_ff, integ = sp.acceleration, state.integral
    err = [vel_sp[0] - vel[0], vel_sp[1] - vel[1], vel_sp[2] - vel[2]]  # NaN where not controlled
    pid = (gains.xy_vel_p * err[0] + integ[0] - gains.xy_vel_d * vel_dot[0],
           gains.xy_vel_p * err[1] + integ[1] - gains.xy_vel_d * vel_dot[1],
           gains.z_vel_p * err[2] + integ[2] - gains.z_vel_d * vel_dot[2])
    acc_sp = [_add_if_finite(a_ff[i], pid[i]) for i in range(3)]
    acc_sp = [a if fin(a) else 0.0 for a in acc_sp]
    thr = _thrust((acc_sp[0], acc_sp[1], acc_sp[2]), gains)
    # vertical anti-windup at the thrust limits
    if (thr[2] >= -gains.thr_min and err[2] >= 0.0) or (thr[2] <= -gains.thr_max and err[2] <= 0.0):
        err[2] = 0.0
    # vertical thrust first, keeping a horizontal margin
    thr_xy = math.hypot(thr[0], thr[1])
    thr_max_sq = gains.thr_max * gains.thr_max
    thr[2] = max(thr[2], -math.sqrt(thr_max_sq - min(thr_xy, gains.thr_xy_margin) ** 2))
    thr_xy_max = math.sqrt(max(thr_max_sq - thr[2] * thr[2], 0.0))
    if thr_xy > thr_xy_max:
        thr[0], thr[1] = thr[0] / thr_xy * thr_xy_max, thr[1] / thr_xy * thr_xy_max
    # tracking anti-windup horizontally (Rundqwist 1990, as PX4)
    scale = GRAVITY_M_S2 / gains.hover_thrust
    produced_n, produced_e = thr[0] * scale, thr[1] * scale
    if acc_sp[0] * acc_sp[0] + acc_sp[1] * acc_sp[1] > produced_n * produced_n + produced_e * produced_e:
        arw = 2.0 / gains.xy_vel_p
        err[0] -= arw * (acc_sp[0] - produced_n)
        err[1] -= arw * (acc_sp[1] - produced_e)
    int_n = integ[0] + gains.xy_vel_i * err[0] * dt_s if fin(err[0]) else integ[0]
    int_e = integ[1] + gains.xy_vel_i * err[1] * dt_s if fin(err[1]) else integ[1]
    int_d = integ[2] + gains.z_vel_i * err[2] * dt_s if fin(err[2]) else integ[2]
    int_d = min(max(int_d, -GRAVITY_M_S2), GRAVITY_M_S2)
    produced = (produced_n, produced_e, thr[2] * scale + GRAVITY_M_S2)
    return produced, ControllerState((int_n, int_e, int_d), vel_sp, (acc_sp[0], acc_sp[1], acc_sp[2]),
                                     (thr[0], thr[1], thr[2]), produced)


def control_at_rate(sp: Setpoint3, pos: Vec3, vel: Vec3, vel_dot: Vec3, state: ControllerState, gains: Gains,
                    dt_s: float, period_s: float = CONTROL_PERIOD_S) -> tuple[Vec3, ControllerState]:
    """:func:`control` run every ``period_s`` (over the time elapsed since its last run), its
    output held in between: PX4 runs the controller at each estimate, not at the simulator's rate."""
    age_s = state.age_s + dt_s
    if age_s < period_s - 1e-9:
        return state.produced, replace(state, age_s=age_s)
    return control(sp, pos, vel, vel_dot, state, gains, age_s)
