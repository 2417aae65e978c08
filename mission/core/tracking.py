"""How the vehicle is made to follow the mission's reference (pure, numpy).

The mission integrates a *reference* (position ``x_ref``, the law's velocity ``u_ref`` and its
acceleration ``a_ref``); this module turns it into the setpoint sent to PX4 (``mission.setpoint``):

- ``"velocity"`` (type_mask 3527): ``v = u_ref + k_p (x_ref - x_p) + i_v``;
- ``"full"`` (type_mask 3072; never bit 512, *force*): ``p = x_ref + l (x_ref - x_p)``,
  ``v = u_ref + k_p (x_ref - x_p)``, ``a = a_ref + c_drag u_ref - k_d (v_p - u_ref) + i_a``, where
  ``l`` is the dimensionless lead, ``c_drag`` [1/s] the drag feed-forward and ``k_d`` [1/s] the
  damping; with ``bias_compensation_s`` ``s`` [s] the position also carries ``+ s b``, ``b`` the
  estimator's velocity less its position's rate (its bias, ``mission.velocity_bias_tau_s``):
  with ``s = 1 / MPC_XY_P`` PX4's velocity setpoint then carries ``+ b`` and the bias no longer
  moves the position PX4 holds. The acceleration sent is clamped to ``accel_limit_m_s2``
  (the command's acceleration limit): PX4 flies the last setpoint on through a stall of ours.

The integral ``i`` ([m/s^2] full, [m/s] velocity) acts on the position error, clamped to
``integral_limit``, and integrates only within ``integral_window_m`` [m] of the reference. After
separation the reference's progress slows when the vehicle lags it by more than ``slow_lag_m``
and stops at ``stop_lag_m`` [m] (:func:`progress`): only time along the law's own path is rescaled.

Frames: local NED [m], [m/s], [m/s^2]. Times [s]. Why each term, the stability check of the lead
and what each was measured against on PX4: docs/tracking.md.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from mission.core.setpoint import Setpoint

SetpointKind = Literal["velocity", "full"]


@dataclass(frozen=True)
class TrackingGains:
    """Gains of the tracking loop (see the module docstring). No defaults: they are built from
    the configuration (``[mission]``, :func:`mission.model.mission_model`), whose schema holds
    the one default of each."""

    kind: SetpointKind
    position_gain_per_s: float
    position_lead: float
    integral_gain: float
    integral_limit: float
    drag_ff_per_s: float
    integral_window_m: float
    damping_per_s: float
    bias_compensation_s: float
    accel_lead_s: float
    accel_lead_filter_s: float
    accel_limit_m_s2: float | None
    slow_lag_m: float | None
    stop_lag_m: float | None


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


#: [m/s] an axis whose velocity the safety filter changed by no more than this keeps its position and
#: acceleration: the acceleration limit scales the whole change, so a floor acting down alone moves
#: north and east by ~1e-6 m/s, which must not cost them their tracking (docs/tracking.md)
AXIS_CHANGED_M_S = 1e-3


def setpoint(x_ref: np.ndarray, u_ref: np.ndarray, a_ref: np.ndarray, x_p: np.ndarray, velocity: np.ndarray,
             integral: np.ndarray, gains: TrackingGains, v_p: np.ndarray | None = None,
             filtered: bool | np.ndarray = False, velocity_bias: np.ndarray | None = None) -> Setpoint:
    """The setpoint to send; the one place that decides velocity-only or full. ``velocity`` [m/s]
    is the (safety-filtered) velocity demand. Velocity only for velocity gains; else a full
    setpoint adds the position (the reference, the lead and, given the estimator's velocity bias
    ``velocity_bias`` [m/s], its compensation) and the acceleration feed-forward (reference
    acceleration, drag feed-forward, integral and, given the vehicle's velocity ``v_p`` [m/s],
    damping). ``filtered``: whether the safety filter changed the velocity, overall (bool) or per
    axis (north, east, down). On the axes it changed the filter wins over the reference, so
    neither the reference position nor its feed-forward may pull the vehicle back there: those
    axes get velocity only (north and east together, as PX4 takes them), the others keep their
    position and acceleration (a floor acting down leaves the horizontal tracking whole)."""
    changed = np.broadcast_to(np.asarray(filtered, dtype=bool), np.shape(velocity))
    axes = (True, True, True)
    if changed.shape == (3,):
        horizontal = not bool(changed[0] or changed[1])
        axes = (horizontal, horizontal, not bool(changed[2]))
    elif changed.any():
        axes = (False, False, False)
    if gains.kind == "velocity" or not any(axes):
        return Setpoint.velocity_only(velocity)
    accel = a_ref + gains.drag_ff_per_s * u_ref + integral
    if gains.damping_per_s > 0 and v_p is not None:
        accel = accel - gains.damping_per_s * (v_p - u_ref)
    if not all(axes):  # what an ignored axis would have added counts for nothing, nor for the limit
        accel = np.where(axes, accel, 0.0)
    limit = gains.accel_limit_m_s2
    size = float(np.linalg.norm(accel))
    if limit is not None and size > limit:  # PX4 holds the last setpoint through a stall of ours
        accel = accel * (limit / size)
    position = x_ref + gains.position_lead * (x_ref - x_p)
    if gains.bias_compensation_s > 0 and velocity_bias is not None:
        position = position + gains.bias_compensation_s * velocity_bias
    return Setpoint.triple(position, velocity, accel, position_axes=axes)


def lead_acceleration(a_ref: np.ndarray, low_passed: np.ndarray | None, gains: TrackingGains,
                      dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The reference's acceleration [m/s^2] as sent, ahead of the vehicle's own acceleration lag,
    and the filter's new state: the lead-lag ``(1 + tau s) / (1 + T s)`` (``tau``
    ``accel_lead_s``, ``T`` ``accel_lead_filter_s``) that turns a vehicle whose acceleration
    follows its setpoint through a first-order lag ``tau`` into one with lag ``T``:
    ``a + (tau / T - 1) (a - lp_T(a))``, ``lp_T`` a first-order low-pass (exact step)."""
    lp = a_ref if low_passed is None else low_passed + (1.0 - np.exp(-dt_s / gains.accel_lead_filter_s)) * (a_ref - low_passed)
    if gains.accel_lead_s <= 0:
        return a_ref, lp
    return a_ref + (gains.accel_lead_s / gains.accel_lead_filter_s - 1.0) * (a_ref - lp), lp


def progress(lag_m: float, gains: TrackingGains) -> float:
    """Rate [0, 1] at which the reference advances in time, given the vehicle's distance from it
    ``lag_m`` [m]: 1 up to ``slow_lag_m``, falling linearly to 0 at ``stop_lag_m`` (1 when unset)."""
    lo, hi = gains.slow_lag_m, gains.stop_lag_m
    if lo is None or hi is None or lag_m <= lo:
        return 1.0
    return max(0.0, (hi - lag_m) / (hi - lo)) if hi > lo else 0.0
