"""The team as its carrier hears it, step by step (pure: no bus, no clock).

Every step the carrier of a team takes a snapshot of each passenger's newest status on its feed
(:meth:`mission.carrier.team_bus.TeamBus.heard`): its name, phase, reported position [m] and
velocity [m/s] NED and the status's receive age [s] on the carrier's clock. From it, every pair of
passengers' distance at the carrier's clock (:func:`hear`): each reported position moved on by its
velocity over its age, as a passenger's pairwise barrier moves its teammates on
(:meth:`mission.core.safety.Neighbours.now`). A pair *counts* towards the closest pair
(:class:`ClosestPair`, the carrier summary's ``closest_pair``) when both were heard within
``safety.passenger_separation_max_age_s`` and either of them flies (:data:`mission.phases.phase.FLYING`),
the rule each passenger's own closest-teammate figure follows (two standing on the deck stand
where their slots are). ``carrier.mcap``'s team topic logs the snapshot and the pairs
(docs/flight-data.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from mission.phases.phase import FLYING, Phase


@dataclass(frozen=True)
class Heard:
    """One passenger as the carrier heard it at a step: ``name``; ``phase`` its phase name;
    ``position_ned_m`` [m] (3,) and ``velocity_ned_m_s`` [m/s] (3,) NED as it reported them;
    ``age_s`` [s] since its status arrived, on the carrier's clock. Everything but the name is
    None while nothing was heard from it (not yet bound, or lost)."""

    name: str
    phase: str | None = None
    position_ned_m: np.ndarray | None = None
    velocity_ned_m_s: np.ndarray | None = None
    age_s: float | None = None

    def now_ned_m(self) -> np.ndarray | None:
        """[m] (3,) NED its position at the carrier's clock: the reported one moved on by the
        reported velocity over the age (None: not heard)."""
        if self.position_ned_m is None or self.age_s is None:
            return None
        v = np.zeros(3) if self.velocity_ned_m_s is None else np.asarray(self.velocity_ned_m_s, dtype=float)
        return np.asarray(self.position_ned_m, dtype=float) + v * self.age_s

    @property
    def flying(self) -> bool:
        return self.phase is not None and Phase[self.phase] in FLYING


@dataclass(frozen=True)
class PairGap:
    """Two passengers ``a`` and ``b`` (names, in the team's order) at a step: ``distance_m`` [m]
    between their positions at the carrier's clock (None: either unheard or heard longer than the
    age limit ago); ``counted``: the distance exists and either of them flies."""

    a: str
    b: str
    distance_m: float | None
    counted: bool


@dataclass(frozen=True)
class TeamHeard:
    """A step's snapshot of the team (``passengers``, the team's order) and every pair of it
    (``pairs``: (0, 1), (0, 2), ..., (1, 2), ...)."""

    passengers: tuple[Heard, ...]
    pairs: tuple[PairGap, ...]

    def closest(self) -> PairGap | None:
        """The counted pair with the least distance at this step (None: none counts)."""
        counted = [g for g in self.pairs if g.counted]
        return min(counted, key=lambda g: g.distance_m or 0.0) if counted else None

    def phase_of(self, name: str) -> str | None:
        return next((h.phase for h in self.passengers if h.name == name), None)


def hear(passengers: Sequence[Heard], max_age_s: float) -> TeamHeard:
    """The snapshot ``passengers`` with every pair's distance [m] at the carrier's clock; a
    passenger heard more than ``max_age_s`` [s] ago is left out of the distances (as the barrier
    leaves a stale teammate out)."""
    now = [None if h.age_s is None or h.age_s > max_age_s else h.now_ned_m() for h in passengers]
    pairs = []
    for i, a in enumerate(passengers):
        for j in range(i + 1, len(passengers)):
            b = passengers[j]
            pa, pb = now[i], now[j]
            d = None if pa is None or pb is None else float(np.linalg.norm(pa - pb))
            pairs.append(PairGap(a.name, b.name, d, d is not None and (a.flying or b.flying)))
    return TeamHeard(tuple(passengers), tuple(pairs))


class ClosestPair:
    """The closest counted pair over the flight as heard: :meth:`update` each step,
    :meth:`summary` for ``carrier.json``."""

    def __init__(self) -> None:
        self.distance_m = math.inf
        self._best: dict[str, Any] | None = None

    def update(self, t_s: float, team: TeamHeard) -> None:
        """Take step ``team`` at the carrier's clock time ``t_s`` [s]."""
        gap = team.closest()
        if gap is None or gap.distance_m is None or not gap.distance_m < self.distance_m:
            return
        self.distance_m = gap.distance_m
        self._best = {"distance_m": round(gap.distance_m, 4), "t_s": round(t_s, 3), "names": [gap.a, gap.b],
                      "phases": [team.phase_of(gap.a), team.phase_of(gap.b)]}

    def summary(self) -> dict[str, Any] | None:
        """``{"distance_m" [m], "t_s" [s] the carrier's clock, "names", "phases"}`` of the closest
        pair heard, or None when no pair ever counted."""
        return None if self._best is None else dict(self._best)
