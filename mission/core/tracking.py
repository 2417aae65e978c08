"""How the vehicle is made to follow the mission's reference (pure, numpy).

The mission integrates a *reference* (position ``x_ref``, the law's velocity ``u_ref`` and its
acceleration ``a_ref``, local NED); this module turns it into the setpoint sent to PX4.

Two kinds of setpoint (``mission.setpoint``):

- ``"velocity"``: velocity only (type_mask 3527). Our own outer loop closes position:
  ``v = u_ref + k_p (x_ref - x_p) + i_v``. PX4's velocity loop then lags a moving reference
  (on PX4 SITL a 2 m/s step never reaches 90 % in 4 s) and drifts sideways: 0.8-1.2 m off the
  dock on real PX4.
- ``"full"``: position + velocity + acceleration (type_mask 3072; never bit 512, which PX4
  reads as *force* and drops). PX4 closes position itself at its own rate (``MPC_XY_P``) with
  velocity and acceleration as feed-forward: ``p = x_ref + l (x_ref - x_p)``,
  ``v = u_ref + k_p (x_ref - x_p)``, ``a = a_ref + c_drag u_ref + i_a``. Our extra position
  feedback goes through the position (the lead ``l``, dimensionless: PX4 multiplies it by its own
  ``MPC_XY_P``) rather than the velocity, so that with ``k_p = 0`` the velocity sent is the law's
  own command, whose smoothness at separation is what the paper promises.

What PX4's loop cannot know is its own steady velocity deficit: a multicopter's drag costs an
acceleration roughly proportional to its velocity, which PX4's small velocity integrator
(``MPC_XY_VEL_I_ACC``) wins back only over many seconds. Two terms supply it:

- ``drag_ff_per_s`` [1/s]: the known part, a feed-forward ``c_drag u_ref`` of the reference
  velocity (SIH's quadrotor: linear drag ``SIH_KDV / SIH_MASS`` = 1/s);
- ``integral_gain`` [1/s^2 for "full", 1/s for "velocity"]: integral action on the position
  error for the rest, clamped to ``integral_limit`` (acceleration [m/s^2] or velocity [m/s]),
  so it cannot wind up while a limit holds the vehicle back; and it integrates only while the
  error is within ``integral_window_m`` [m] (a vehicle far from the reference is catching up,
  not suffering a steady deficit: integrating then is what made PX4 overshoot the target by
  1.8 m and ring).

The lead stiffens the loop PX4 closes: its velocity loop (``MPC_XY_VEL_P_ACC`` 1.8/s) then
drives a position gain of ``MPC_XY_P (1 + l)`` = 3.4/s through the airframe's tilt lag (~0.28 s
fitted on SIH): ``tau s^3 + s^2 + 1.8 s + 1.8 x 3.4 = 0``, which is only just stable (Routh:
1.8 > 0.28 x 6.2 = 1.7, and less with the command's own delays): the passenger rings about a
steadily moving dock (period ~2.6 s, +-0.25 m seen on PX4 behind the SIH rover). With ``k_d``
below the Routh condition reads ``1.8 + k_d > 1.7``.
``damping_per_s`` [1/s] adds velocity damping through the acceleration feed-forward (full
setpoints): ``- k_d (v_p - u_ref)``, the vehicle's velocity ``v_p`` against the reference's, as if
PX4's velocity gain were ``1.8 + k_d`` about the reference velocity.

After separation the reference is the law integrated in time; when the vehicle lags it by more
than ``slow_lag_m`` [m] the reference's progress is slowed, and it waits at ``stop_lag_m`` [m]
(:func:`progress`). The law is autonomous, so this only rescales time along the law's own path:
the reference never runs away from a vehicle that cannot follow (on PX4 the reference stopped at
the target 0.7 m ahead of a vehicle still doing 2 m/s, which then overshot).

Frames: local NED [m], [m/s], [m/s^2]. Times [s].
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

SetpointKind = Literal["velocity", "full"]


@dataclass(frozen=True)
class TrackingGains:
    """Gains of the tracking loop (see the module docstring)."""

    kind: SetpointKind = "velocity"
    position_gain_per_s: float = 1.0
    position_lead: float = 0.0
    integral_gain: float = 0.0
    integral_limit: float = 2.0
    drag_ff_per_s: float = 0.0
    integral_window_m: float = 0.5
    damping_per_s: float = 0.0
    slow_lag_m: float | None = None
    stop_lag_m: float | None = None


@dataclass(frozen=True)
class Setpoint:
    """One setpoint for the vehicle: velocity [m/s] always; position [m] and acceleration
    [m/s^2] for a full setpoint (None: velocity only)."""

    velocity_ned_m_s: np.ndarray
    position_ned_m: np.ndarray | None = None
    acceleration_ned_m_s2: np.ndarray | None = None

    @property
    def full(self) -> bool:
        return self.position_ned_m is not None


def velocity_demand(x_ref: np.ndarray, u_ref: np.ndarray, x_p: np.ndarray, integral: np.ndarray,
                    gains: TrackingGains) -> np.ndarray:
    """The velocity [m/s] asked of the vehicle: the law's velocity, our pull to the reference and,
    for velocity setpoints, the integral term (a velocity)."""
    v = u_ref + gains.position_gain_per_s * (x_ref - x_p)
    return v + integral if gains.kind == "velocity" and gains.integral_gain > 0 else v


def update_integral(integral: np.ndarray, x_ref: np.ndarray, x_p: np.ndarray, gains: TrackingGains,
                    dt_s: float) -> np.ndarray:
    """Integral state after one step of ``dt_s`` [s] (its norm clamped to the limit)."""
    if gains.integral_gain <= 0:
        return integral
    error = x_ref - x_p
    if float(np.linalg.norm(error)) > gains.integral_window_m:
        return integral
    new = integral + gains.integral_gain * error * dt_s
    size = float(np.linalg.norm(new))
    return new * (gains.integral_limit / size) if size > gains.integral_limit else new


def setpoint(x_ref: np.ndarray, u_ref: np.ndarray, a_ref: np.ndarray, x_p: np.ndarray, velocity: np.ndarray,
             integral: np.ndarray, gains: TrackingGains, v_p: np.ndarray | None = None) -> Setpoint:
    """The setpoint to send: ``velocity`` [m/s] is the (safety-filtered) velocity demand; a full
    setpoint adds the reference position and the acceleration feed-forward (reference
    acceleration, drag feed-forward, integral and, given the vehicle's velocity ``v_p`` [m/s],
    damping)."""
    if gains.kind == "velocity":
        return Setpoint(velocity)
    accel = a_ref + gains.drag_ff_per_s * u_ref + integral
    if gains.damping_per_s > 0 and v_p is not None:
        accel = accel - gains.damping_per_s * (v_p - u_ref)
    return Setpoint(velocity, x_ref + gains.position_lead * (x_ref - x_p), accel)


def progress(lag_m: float, gains: TrackingGains) -> float:
    """Rate [0, 1] at which the reference advances in time, given the vehicle's distance from it
    ``lag_m`` [m]: 1 up to ``slow_lag_m``, falling linearly to 0 at ``stop_lag_m`` (1 when unset)."""
    lo, hi = gains.slow_lag_m, gains.stop_lag_m
    if lo is None or hi is None or lag_m <= lo:
        return 1.0
    return max(0.0, (hi - lag_m) / (hi - lo)) if hi > lo else 0.0
