"""The carrier's recovery course: what it drives while the passenger comes home (pure; no clock).

While the passenger returns, holds off, approaches and docks (duty RECOVER, carrier mode
RECOVERING) the carrier keeps a steady, announced course, so that the passenger can predict its
dock point: first the scripted legs of ``carrier.recovery_course`` (each a NED heading [deg], a
speed [m/s] and a duration [s], driven in order from the start of the recovery), then for ever the
steady course ``carrier.recovery_heading_deg`` at ``carrier.recovery_speed_m_s`` (speed 0: the
carrier stops and waits). The steady heading defaults to *away from the target*: the bearing from
the target to where the carrier stands when the recovery begins (planar), so the steady course
never brings it closer to the target.

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


def _velocity(heading_deg: float, speed_m_s: float) -> np.ndarray:
    h = math.radians(heading_deg)
    return np.array([speed_m_s * math.cos(h), speed_m_s * math.sin(h)])
