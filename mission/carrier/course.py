"""The carrier's recovery course: what it drives while the passenger comes home (pure; no clock).

While the passenger returns, holds off, approaches and docks (duty RECOVER, carrier mode
RECOVERING) the carrier keeps a steady, announced course, so that the passenger can predict its
dock point: first the scripted legs of ``carrier.recovery_course`` (each a NED heading [deg], a
speed [m/s] and a duration [s], driven in order from the start of the recovery), then for ever the
steady course ``carrier.recovery_heading_deg`` at ``carrier.recovery_speed_m_s`` (speed 0: the
carrier stops and waits). The steady heading defaults to *away from the target*: the bearing from
the target to where the carrier stands when the recovery begins (planar), so the steady course
never brings it closer to the target, turned as little as clears the other targets' keep-outs
(:func:`clear_heading_deg`).

The course is a velocity request only: the controller passes it through the same CBF filter,
speed and acceleration limits as the law's command (:func:`mission.core.tick.carrier_tick`) and
then the P3 guard, so a turn between legs is flown at the carrier's acceleration limit and P3
holds whatever the course says. Headings: NED, 0 north, 90 east [deg]; velocities (north, east)
[m/s].
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Leg:
    """One leg of the course: heading_deg [deg] NED, speed_m_s [m/s] >= 0, duration_s [s] > 0."""

    heading_deg: float
    speed_m_s: float
    duration_s: float


@dataclass(frozen=True)
class RecoveryCourse:
    """The scripted legs, then the steady course: ``heading_deg`` [deg] NED (None: away from the
    target) at ``speed_m_s`` [m/s]."""

    legs: tuple[Leg, ...] = ()
    heading_deg: float | None = None
    speed_m_s: float = 0.0

    @classmethod
    def from_lists(cls, legs: Sequence[Sequence[float]], heading_deg: float | None, speed_m_s: float) -> RecoveryCourse:
        """The course from the configuration's ``[[heading_deg, speed_m_s, duration_s], ...]``."""
        return cls(tuple(Leg(float(h), float(v), float(d)) for h, v, d in legs), heading_deg, speed_m_s)

    def velocity_ned_m_s(self, elapsed_s: float, away_heading_deg: float) -> np.ndarray:
        """The course's velocity (north, east) [m/s] ``elapsed_s`` [s] after the recovery began;
        ``away_heading_deg`` [deg]: the bearing from the target to the carrier then
        (:func:`away_heading_deg`), the steady course's heading when none is configured."""
        t = max(elapsed_s, 0.0)
        for leg in self.legs:
            if t < leg.duration_s:
                return _velocity(leg.heading_deg, leg.speed_m_s)
            t -= leg.duration_s
        heading = away_heading_deg if self.heading_deg is None else self.heading_deg
        return _velocity(heading, self.speed_m_s)


def away_heading_deg(carrier_ned_m: np.ndarray, target_ned_m: np.ndarray) -> float:
    """The NED heading [deg] from the target to the carrier, horizontally (0 when they coincide)."""
    d = np.asarray(carrier_ned_m, dtype=float)[:2] - np.asarray(target_ned_m, dtype=float)[:2]
    if float(np.hypot(d[0], d[1])) < 1e-9:
        return 0.0
    return math.degrees(math.atan2(float(d[1]), float(d[0])))


#: [deg] the steps in which :func:`clear_heading_deg` turns the away heading, and the most it turns
CLEAR_STEP_DEG = 1.0
CLEAR_MAX_DEG = 90.0


def clear_heading_deg(carrier_ned_m: np.ndarray, away_deg: float, centers_m: np.ndarray, radii_m: np.ndarray,
                      margin_m: float, speed_m_s: float, gain_per_s: float, band_m: float = 0.0) -> float:
    """The steady course's default heading [deg] NED: the away heading ``away_deg``, or the
    nearest to it (within :data:`CLEAR_MAX_DEG` either side, so the course never closes on the
    target it leaves) whose ray from the carrier at ``carrier_ned_m`` [m] passes every other
    target's keep-out (planar ``centers_m`` (m, 2+) [m], ``radii_m`` (m,) [m]: the carrier's
    other keep-out rows, :func:`mission.core.tick.target_keep_outs`) at least
    ``sqrt((r + margin)^2 + (v / gain)^2)`` from its centre, where a straight pass at
    ``speed_m_s`` [m/s] never wakes the row (``2 (x - o) . u >= -gain h``, ``gain_per_s`` [1/s]
    the barrier's), and at least ``r + margin + band_m`` (the band in which the carrier begins
    to veer round a keep-out it heads into, :func:`mission.core.tick.round_keep_outs`); a keep-out the carrier stands inside of, or closer than that, counts as passed
    when the ray leaves it). Steered round a keep-out by its row instead, the carrier turned at
    20 deg/s under a passenger on its approach, which went round (team Monte-Carlo, docs/team.md).
    None clear: the heading that passes them at the largest shortfall's least."""
    centers = np.asarray(centers_m, dtype=float).reshape(len(radii_m), -1)[:, :2] if len(radii_m) else np.zeros((0, 2))
    if not len(centers):
        return away_deg
    x = np.asarray(carrier_ned_m, dtype=float)[:2]
    row = np.asarray(radii_m, dtype=float) + margin_m
    need = np.maximum(np.sqrt(row ** 2 + (speed_m_s / max(gain_per_s, 1e-9)) ** 2), row + band_m)
    rel = centers - x
    steps = int(round(CLEAR_MAX_DEG / CLEAR_STEP_DEG))
    best, best_short = away_deg, math.inf
    for k in range(2 * steps + 1):
        delta = CLEAR_STEP_DEG * ((k + 1) // 2) * (1 if k % 2 else -1)
        h = math.radians(away_deg + delta)
        u = np.array([math.cos(h), math.sin(h)])
        along = rel @ u
        passing = np.where(along > 0.0, np.abs(rel[:, 0] * u[1] - rel[:, 1] * u[0]), np.inf)  # the ray's least distance
        short = float(np.max(need - passing))
        if short <= 0.0:
            return away_deg + delta
        if short < best_short:
            best, best_short = away_deg + delta, short
    return best


def _velocity(heading_deg: float, speed_m_s: float) -> np.ndarray:
    h = math.radians(heading_deg)
    return np.array([speed_m_s * math.cos(h), speed_m_s * math.sin(h)])
