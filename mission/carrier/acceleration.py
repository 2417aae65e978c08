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

from mission.carrier.backends import OwnState
from mission.carrier.tracking import along_heading


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


def inertial_sample(state: OwnState, velocity_ned_m_s: np.ndarray, dim: int, along: bool) -> tuple[float, np.ndarray]:
    """The time [s] and velocity [m/s] NED (3,) the carrier's acceleration is measured from: where
    its ``state`` is a GNSS fix, the robot's inertial state's (``state.inertial``: its first
    ``dim`` axes; for a robot that moves ``along`` its heading, the part along its own heading);
    else the ``velocity_ned_m_s`` the carrier publishes, at the state's time. Differentiated from
    10 Hz fixes with 0.2 m/s of noise the acceleration swung past the passenger's HOLDOFF limit at
    every tick, and the fixes' 0.2 s latency puts it that late behind a rover's pull-away, which
    is what the riding passenger feeds it forward for (docs/relnav.md, "The rover's own
    acceleration")."""
    nav = state.inertial
    if nav is None:
        return state.t_s, velocity_ned_m_s
    v = np.zeros(3)
    v[:dim] = np.asarray(nav.velocity_ned_m_s, dtype=float)[:dim]
    if along and nav.yaw_rad is not None:
        v = along_heading(v, nav.yaw_rad)
    return nav.t_s, v
