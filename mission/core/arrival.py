"""Arrival at the target judged on a window of the vehicle's estimated positions (pure, numpy).

A real estimate's velocity is a poor judge of rest. PX4 SITL's velocity estimate errs by
0.15-0.25 m/s RMS per horizontal axis for seconds at a time while its position estimate stands
still (docs/px4-hold.md): a passenger held on the target within centimetres reported 0.3-0.45
m/s for 3 s, so a rule on one velocity sample (slower than 0.3 m/s for 1 s) kept it from
arriving for 4-11 s. The positions it reports are what PX4 holds, and they are calm.

The rule: the vehicle has arrived once, over the last ``dwell_s`` [s], every position it
reported lay within ``radius_m`` [m] of the target and, if ``max_speed_m_s`` [m/s] is set, those
positions lay within ``max_speed_m_s * dwell_s / 2`` of their mean: what a vehicle drifting at
that speed covers, so a drift, a swing or a dance through the radius all wait, and the velocity
estimate is not consulted. Frames: NED [m]; times [s] on the controller's clock.
"""
from __future__ import annotations

import numpy as np

Window = tuple[tuple[float, np.ndarray], ...]


def extend(window: Window, t_s: float, position_ned_m: np.ndarray, inside: bool, dwell_s: float) -> Window:
    """The window after the sample at ``t_s``: emptied when the vehicle is outside the radius,
    else with the sample added and those older than ``dwell_s`` (and a margin of a sample) dropped."""
    if not inside:
        return ()
    kept = tuple(s for s in window if s[0] >= t_s - dwell_s - 1e-9)
    return (*kept, (t_s, np.asarray(position_ned_m, dtype=float).copy()))


def spread_m(window: Window) -> float:
    """How far [m] the window's positions lie from their mean, at most (0 for an empty window)."""
    if not window:
        return 0.0
    x = np.stack([s[1] for s in window])
    return float(np.linalg.norm(x - x.mean(axis=0), axis=1).max())


def arrived(window: Window, t_s: float, dwell_s: float, max_speed_m_s: float | None, dt_s: float) -> bool:
    """The window spans ``dwell_s`` (within half a tick ``dt_s``) and, if ``max_speed_m_s`` is
    set, its positions spread no farther than a vehicle at that speed would in the dwell:
    ``max_speed_m_s * dwell_s / 2`` from their mean (a steady drift or a swing alike)."""
    if not window or t_s - window[0][0] < dwell_s - 0.5 * dt_s:
        return False
    return max_speed_m_s is None or spread_m(window) <= 0.5 * max_speed_m_s * dwell_s
