"""Tracking law (pure): the law's planar velocity command made into what the carrier can do.

A holonomic carrier follows any planar velocity. A differential-drive (unicycle) or Ackermann
carrier moves only along its heading ``psi`` [rad, NED, from north towards east]: it is given a
forward speed ``v`` [m/s] and a yaw rate ``omega`` [rad/s]. The standard law for such robots
(heading-error steering with cosine speed scaling, e.g. Siegwart & Nourbakhsh, "Introduction to
Autonomous Mobile Robots", sec. 3.6)::

    psi_d = atan2(u_e, u_n),   e = wrap(psi_d - psi)
    omega = sat(k_psi e, omega_max)       Ackermann: also |omega| <= |v| tan(delta_max) / L
    v     = |u| max(cos e, s_min)          s_min = 0 (diff-drive: turn in place), > 0 (Ackermann:
                                           it can only turn while it moves)

so the robot slows while it is misaligned and never drives fast the wrong way. The motion it
really makes, ``v (cos psi, sin psi)``, is what the P3 guard caps (:func:`~.guard.guard_along_heading`).

For a PX4 rover in OFFBOARD the velocity setpoint becomes a speed ``|v_sp|`` and a bearing
``atan2(v_sp)`` that PX4's own attitude loop steers to (``AckermannOffboardMode.cpp``), so the
command sent is ``v (cos psi_d, sin psi_d)``: the scaled speed towards the desired bearing.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from mission.core.geodesy import wrap_pi

Kinematics = Literal["holonomic", "diff_drive", "ackermann"]
AUTOPILOT_SPEED_TH_M_S = 0.1  # [m/s] PX4's RO_SPEED_TH (default): a speed estimate below it reads as 0
SPEED_LOOP_ERROR_MAX_M_S = 1.0  # [m/s] the most of an autopilot's speed error corrected (its EKF erred <= 0.9 m/s)
TURN_STEP_RAD = 0.5 * math.pi  # [rad] a turn set a way round steers to at most this far ahead of the heading
SPEED_LOOP_FLOOR_M_S = 0.01  # [m/s] a corrected speed asked never falls below this (nor above the speed asked)


@dataclass(frozen=True)
class TrackingParams:
    """kind; heading_gain [1/s]; max_yaw_rate_rad_s [rad/s]; min_speed_fraction (Ackermann
    creep, in [0, 1]); wheelbase_m [m] and max_steer_rad [rad] (Ackermann); speed_loop_correction
    (diff-drive/Ackermann, in [0, 1]: :func:`speed_loop_corrected`)."""

    kind: Kinematics = "holonomic"
    heading_gain: float = 2.0
    max_yaw_rate_rad_s: float = 1.0
    min_speed_fraction: float = 0.3
    wheelbase_m: float = 0.3
    max_steer_rad: float = 0.5
    speed_loop_correction: float = 0.0


@dataclass(frozen=True)
class Tracked:
    """speed_m_s [m/s] forward (>= 0); yaw_rate_rad_s [rad/s]; bearing_rad [rad] desired
    heading; velocity_ned_m_s (2,) (holonomic: the command's shape) the motion along the current heading [m/s]; setpoint_ned_m_s
    (2,) what a velocity-setpoint vehicle is sent [m/s]."""

    speed_m_s: float
    yaw_rate_rad_s: float
    bearing_rad: float
    velocity_ned_m_s: np.ndarray
    setpoint_ned_m_s: np.ndarray


def heading_of(speed_m_s: float, yaw_rad: float) -> np.ndarray:
    """Planar velocity (2,) [m/s] NED of forward speed ``speed_m_s`` at heading ``yaw_rad``."""
    return np.array([speed_m_s * math.cos(yaw_rad), speed_m_s * math.sin(yaw_rad)])


def along_heading(v_ned_m_s: np.ndarray, yaw_rad: float) -> np.ndarray:
    """The velocity [m/s] NED a robot without sideslip has: the planar part of ``v_ned_m_s``
    projected on the heading ``yaw_rad`` [rad] (its forward speed along it); any third component
    is kept. What a diff-drive or Ackermann carrier publishes: its heading is a better estimate
    than its estimator's velocity direction (docs/carrier.md, what the passenger rides on)."""
    out = np.array(v_ned_m_s, dtype=float)
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    forward = c * out[0] + s * out[1]
    out[0], out[1] = forward * c, forward * s
    return out


def track(u_ned_m_s: np.ndarray, yaw_rad: float, p: TrackingParams, turn: int = 0) -> Tracked:
    """Forward speed and yaw rate following the planar command ``u_ned_m_s`` (first two
    components used) from heading ``yaw_rad``; see the module docstring. ``turn`` (diff-drive
    and Ackermann): 0 the shortest way onto the command's bearing; +1 (towards east from north)
    or -1 that way round, however long: then the bearing steered to (``bearing_rad``, and the
    setpoint's) is at most :data:`TURN_STEP_RAD` ahead of the heading that way, so that an
    autopilot that steers the shortest way to a setpoint's bearing (PX4's rover) turns that way
    too (:meth:`mission.carrier.guard.P3Guard.away_turn`: round away from a target)."""
    un, ue = float(u_ned_m_s[0]), float(u_ned_m_s[1])
    speed_des = math.hypot(un, ue)
    if p.kind == "holonomic":
        bearing = math.atan2(ue, un) if speed_des > 1e-9 else yaw_rad
        v = np.array(u_ned_m_s, dtype=float)  # every component (a non-planar carrier keeps its third)
        return Tracked(speed_des, 0.0, bearing, v, v.copy())
    if speed_des <= 1e-9:
        return Tracked(0.0, 0.0, yaw_rad, np.zeros(2), np.zeros(2))
    bearing = math.atan2(ue, un)
    err = wrap_pi(bearing - yaw_rad)
    if turn and (turn > 0) != (err > 0):  # the long way round: the turn left to make that way
        err = math.copysign(2.0 * math.pi - abs(err), turn)
    if turn and abs(err) > TURN_STEP_RAD:
        bearing = wrap_pi(yaw_rad + math.copysign(TURN_STEP_RAD, err))
    floor = p.min_speed_fraction if p.kind == "ackermann" else 0.0
    speed = speed_des * max(math.cos(err), floor)
    rate_max = p.max_yaw_rate_rad_s
    if p.kind == "ackermann":
        rate_max = min(rate_max, speed * math.tan(p.max_steer_rad) / p.wheelbase_m)
    omega = min(max(p.heading_gain * err, -rate_max), rate_max)
    return Tracked(speed, omega, bearing, heading_of(speed, yaw_rad), heading_of(speed, bearing))


def own_speed_m_s(velocity_ned_m_s: np.ndarray, yaw_rad: float | None, kind: str) -> float:
    """How fast [m/s] a vehicle whose estimator says ``velocity_ned_m_s`` [m/s] NED moves: a
    diff-drive or Ackermann vehicle (``kind``) with a heading ``yaw_rad`` [rad] moves only along it,
    so its forward speed's size (the sideways part is the estimator's error: PX4's SIH rover,
    standing, was estimated at 0.3-1.1 m/s sideways for seconds); otherwise, or without a heading,
    the horizontal speed. What the gentle start calls moving and the MAVLink backend calls at rest."""
    vn, ve = float(velocity_ned_m_s[0]), float(velocity_ned_m_s[1])
    if kind == "holonomic" or yaw_rad is None:
        return math.hypot(vn, ve)
    return abs(math.cos(yaw_rad) * vn + math.sin(yaw_rad) * ve)


def autopilot_speed_m_s(velocity_ned_m_s: np.ndarray, yaw_rad: float) -> float:
    """The forward speed [m/s] a PX4 rover's speed loop measures from its estimator's velocity
    ``velocity_ned_m_s`` [m/s] NED at heading ``yaw_rad`` [rad]: the horizontal velocity's size signed
    by its forward part, 0 below :data:`AUTOPILOT_SPEED_TH_M_S` (``AckermannVelControl.cpp``,
    ``updateSubscriptions``). Standing with its EKF at -0.23 m/s forward and 0.18 sideways it reads
    -0.29; creeping forward at 0.1 with the same sideways error, +0.2."""
    vn, ve = float(velocity_ned_m_s[0]), float(velocity_ned_m_s[1])
    forward, size = math.cos(yaw_rad) * vn + math.sin(yaw_rad) * ve, math.hypot(vn, ve)
    return math.copysign(size, forward) if size > AUTOPILOT_SPEED_TH_M_S else 0.0


def speed_loop_corrected(cmd: Tracked, yaw_rad: float | None, velocity_ned_m_s: np.ndarray,
                         motion_ned_m_s: np.ndarray, p: TrackingParams, guarded: bool = False) -> Tracked:
    """``cmd`` for a diff-drive or Ackermann vehicle whose own speed loop closes on its estimator's
    velocity ``velocity_ned_m_s`` [m/s] NED (PX4's rover): with ``p.speed_loop_correction`` = k > 0
    the forward speed asked is raised by k times that loop's error, e = :func:`autopilot_speed_m_s`
    less the forward part of ``motion_ned_m_s`` [m/s] NED (its velocity made consistent with its
    position: :meth:`mission.carrier.step.CarrierStepper.motion_m_s`), e within
    +-:data:`SPEED_LOOP_ERROR_MAX_M_S`; never below :data:`SPEED_LOOP_FLOOR_M_S` (nor the speed
    asked, if less); never above the speed asked while ``guarded`` (a P3 guard cut it this step: in
    lb8 the guard braked the rover 1.1 s before the separation, its position read it rolling back,
    the correction raised the speed asked to 1.1-1.4 m/s, and it leapt from a stop to 1.55 m/s under
    the riding passenger, 7.60 m from the target). A stop, a heading unknown or k = 0 leave ``cmd``
    as it is. The motion (``velocity_ned_m_s`` of ``cmd``) stays what the vehicle is to do; the speed
    and the setpoint are what it is asked.

    Why: PX4's throttle is ``s / RO_MAX_THR_SPEED + RO_SPEED_P (s - m) + I`` for the speed asked ``s``
    and the speed it measures ``m`` (``RoverControl::speedControl``). At leg 2's start the SIH
    rover stood with its EKF reading -0.3 m/s (backwards), so the first ask already pushed; it broke
    free asked 0.1-0.3 m/s, its estimate flipped to +0.3 as it crept, its throttle fell below the
    rolling friction, it stopped, read -0.2 again, and by then asked 0.7 m/s it leapt to 1.5-1.7 m/s
    (SIH's static friction is 0.5 g, its rolling friction 0.3 g: ``Sih::generate_rover_ackermann_dynamics``)
    and the riding passenger trailed 0.36-0.37 m (docs/recovery.md, "On real PX4"). Asked
    ``s + k e``, the throttle's proportional and feed-forward terms together see the consistent
    speed's error for k = RO_SPEED_P / (RO_SPEED_P + 1 / RO_MAX_THR_SPEED)."""
    k = p.speed_loop_correction
    if k <= 0 or cmd.speed_m_s <= 0 or yaw_rad is None or p.kind == "holonomic":
        return cmd
    forward = math.cos(yaw_rad) * float(motion_ned_m_s[0]) + math.sin(yaw_rad) * float(motion_ned_m_s[1])
    error = min(max(autopilot_speed_m_s(velocity_ned_m_s, yaw_rad) - forward, -SPEED_LOOP_ERROR_MAX_M_S),
                SPEED_LOOP_ERROR_MAX_M_S)
    speed = max(cmd.speed_m_s + k * (min(error, 0.0) if guarded else error), min(cmd.speed_m_s, SPEED_LOOP_FLOOR_M_S))
    scale = speed / cmd.speed_m_s
    return Tracked(speed, cmd.yaw_rate_rad_s, cmd.bearing_rad, cmd.velocity_ned_m_s, cmd.setpoint_ned_m_s * scale)


class SpeedCalibration:
    """``carrier.speed_ratio_tau_s`` > 0: a vehicle whose own speed loop runs fast is asked for
    ``v / r``, where ``r`` in [1, 3] is its measured forward speed over the speed last asked,
    low-passed with that time constant ``tau_s`` [s] (docs/carrier.md). Never more than asked."""

    def __init__(self, tau_s: float) -> None:
        self.tau_s = tau_s
        self.ratio = 1.0  # measured / asked forward speed, low-passed
        self._last_speed_cmd = 0.0  # [m/s] the forward speed last asked

    def asked(self, cmd: Tracked, yaw: float, v_meas: np.ndarray, dt_s: float) -> Tracked:
        """What to ask of the vehicle at heading ``yaw`` [rad], measured velocity ``v_meas``
        [m/s] NED, so that it does ``cmd`` (``cmd`` itself when off or ``r`` is 1)."""
        if self.tau_s <= 0:
            return cmd
        forward = math.cos(yaw) * float(v_meas[0]) + math.sin(yaw) * float(v_meas[1])
        if self._last_speed_cmd > 0.3 and dt_s > 0:  # a ratio of small speeds is noise
            alpha = 1.0 - math.exp(-dt_s / self.tau_s)
            self.ratio += alpha * (forward / self._last_speed_cmd - self.ratio)
        ratio = min(max(self.ratio, 1.0), 3.0)
        self._last_speed_cmd = cmd.speed_m_s / ratio
        if ratio == 1.0:
            return cmd
        asked = cmd.speed_m_s / ratio  # the motion (velocity_ned_m_s) stays what the vehicle will do
        return Tracked(asked, cmd.yaw_rate_rad_s, cmd.bearing_rad, cmd.velocity_ned_m_s, cmd.setpoint_ned_m_s / ratio)
