"""A vehicle's estimated velocity made consistent with its own estimated position (pure).

An estimator (PX4's EKF2) can let velocity and position disagree for seconds; a vehicle that feeds
such a velocity forward lags what the position does. The carrier publishes, and the passenger
observes, its velocity corrected by a complementary filter: the bias ``b`` is the difference
between the position's rate between two successive samples and their mean velocity (exact for a
velocity linear in time), low-passed with time constant ``tau_s`` [s] (first order, exact for any
sample spacing); the velocity used is ``v + b``. Fast changes come from the estimator's velocity,
the slow drift from its position. Frames: NED [m], [m/s]; times [s] on the caller's clock. What
was measured on PX4 SITL: docs/carrier.md (velocities consistent with positions).
"""
from __future__ import annotations

import math

import numpy as np


class PositionConsistentVelocity:
    """The velocity plus the low-passed bias of its position's rate; :meth:`update` once a tick.
    With ``across_tau_s`` [s] the bias's part across the heading given to :meth:`update` (yaw
    from north, the horizontal perpendicular) is low-passed with that time constant instead, its
    other parts with ``tau_s``."""

    def __init__(self, tau_s: float, across_tau_s: float | None = None) -> None:
        if tau_s <= 0:
            raise ValueError(f"tau_s must be > 0, got {tau_s!r}")
        if across_tau_s is not None and across_tau_s <= 0:
            raise ValueError(f"across_tau_s must be > 0, got {across_tau_s!r}")
        self.tau_s = tau_s
        self.across_tau_s = across_tau_s
        self._last: tuple[float, np.ndarray, np.ndarray] | None = None
        self.bias: np.ndarray | None = None  # [m/s]; None until two samples were seen

    def update(self, t_s: float, position_m: np.ndarray, velocity_m_s: np.ndarray,
               yaw_rad: float | None = None) -> np.ndarray:
        """Take the sample (time ``t_s`` [s], position [m], velocity [m/s], and the heading
        ``yaw_rad`` [rad] for ``across_tau_s``); returns the velocity corrected by the bias so far.
        A sample no newer than the last one changes nothing."""
        x = np.asarray(position_m, dtype=float).copy()
        v = np.asarray(velocity_m_s, dtype=float).copy()
        if self._last is not None:
            t0, x0, v0 = self._last
            dt = t_s - t0
            if dt <= 0:
                return v if self.bias is None else v + self.bias
            raw = (x - x0) / dt - 0.5 * (v + v0)
            if self.bias is None:
                self.bias = np.zeros_like(raw)
            gain = 1.0 - math.exp(-dt / self.tau_s)
            change = gain * (raw - self.bias)
            if self.across_tau_s is not None and yaw_rad is not None and raw.shape[0] >= 2:
                across = np.zeros_like(raw)
                across[:2] = -math.sin(yaw_rad), math.cos(yaw_rad)  # the horizontal perpendicular to the heading
                # the part across the heading moves with its own gain instead
                change += (1.0 - math.exp(-dt / self.across_tau_s) - gain) * float(np.dot(raw - self.bias, across)) * across
            self.bias = self.bias + change
        self._last = (t_s, x, v)
        return v if self.bias is None else v + self.bias

    def reset(self) -> None:
        """Forget the last sample (the own state went stale: the next difference would span the
        gap); the bias is kept (it drifts slowly)."""
        self._last = None
