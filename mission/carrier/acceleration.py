"""The carrier's measured acceleration (pure): what it publishes for the passenger's feed-forward.

The passenger rides the dock point and feeds its acceleration forward to PX4. It can predict it
from the carrier law, but a real carrier does not follow its law exactly (a PX4 rover sticks at
rest, then leaps: docs/carrier.md). So the carrier sends what it measures: the change of its own
velocity between successive own-state samples, low-passed with time constant ``tau_s`` [s] (first
order, exact for any sample spacing). Frames: NED [m/s], [m/s^2]; times [s] on the carrier's clock.
"""
from __future__ import annotations

import math

import numpy as np


class AccelerationEstimate:
    """Low-passed difference of velocity samples; :meth:`update` once per control tick."""

    def __init__(self, tau_s: float) -> None:
        if tau_s <= 0:
            raise ValueError(f"tau_s must be > 0, got {tau_s!r}")
        self.tau_s = tau_s
        self._last: tuple[float, np.ndarray] | None = None
        self.value: np.ndarray | None = None  # [m/s^2]; None until two samples were seen

    def update(self, t_s: float, velocity_m_s: np.ndarray) -> np.ndarray | None:
        """Take the sample (time ``t_s`` [s], velocity [m/s]); a sample no newer than the last one is
        ignored (the same own state seen on two ticks). Returns the estimate."""
        v = np.asarray(velocity_m_s, dtype=float).copy()
        if self._last is None:
            self._last = (t_s, v)
            return self.value
        t0, v0 = self._last
        dt = t_s - t0
        if dt <= 0:
            return self.value
        self._last = (t_s, v)
        raw = (v - v0) / dt
        if self.value is None:
            self.value = raw
        else:
            self.value = self.value + (1.0 - math.exp(-dt / self.tau_s)) * (raw - self.value)
        return self.value

    def reset(self) -> None:
        """Forget everything (the own state went stale: the next difference would span the gap)."""
        self._last, self.value = None, None
