"""Several passengers leaving one deck together, flown in-process on the pure law and filter
(:func:`mission.core.tick.passenger_tick`), the pairwise separation barrier's proving ground
(docs/team.md, "Keeping passengers apart").

Each passenger separates at ``t = 0`` from its slot on a stopped deck (its latched anchor) and
flies the paper's law to its own target through the safety filter, the others as its
:class:`~mission.core.safety.Neighbours`: their states of ``delay_ticks`` ticks ago, with that age,
as a bus would bring them; its rows phase in from ``t = 0`` as the mission's do
(``safety.separation_phase_in_s``). The vehicles follow their commands exactly (no dynamics): what is
measured is the barrier, not the tracking. A passenger that reaches its target (within
``arrival_radius_m``) holds there and stops reacting, as one handed to PX4's Hold does. Arrays:
``B`` scenarios of ``k`` passengers, NED [m], [m/s], [s].
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from mission.core.law import LawParams, norm
from mission.core.safety import Neighbours, Obstacles, SafetyConfig
from mission.core.tick import TickModel, passenger_tick


@dataclass(frozen=True)
class TeamFlight:
    """What a batch of team flights did: min_distance_m (B,) the least distance between any two
    passengers over the flight [m]; shortfall_m (B,) how far a pair came inside what the barrier
    keeps [m] (0: never), the separation distance once the pair has been that far apart, before
    that the largest distance it has had (a pair that starts closer is held, not pushed apart);
    arrived_s (B, k) when each reached its target
    (nan: not in the flight's time); infeasible (B,) ticks on which a filter had no solution;
    final_m (B, k, n) where each ended [m]; distance_m (T, B) the least pairwise distance at every
    tick (with ``record``, else None)."""

    min_distance_m: np.ndarray
    shortfall_m: np.ndarray
    arrived_s: np.ndarray
    infeasible: np.ndarray
    final_m: np.ndarray
    distance_m: np.ndarray | None = None


def pair_distances(x: np.ndarray) -> np.ndarray:
    """The distance [m] between each two of the ``k`` passengers of each scenario, x (B, k, n) -> (B, pairs)."""
    k = x.shape[-2]
    i, j = np.triu_indices(k, 1)
    return norm(x[..., i, :] - x[..., j, :])


def fly_team(slots: np.ndarray, targets: np.ndarray, law: LawParams, safety: SafetyConfig, dt_s: float, duration_s: float,
             *, arrival_radius_m: float = 0.5, delay_ticks: int = 1, separate: bool = True,
             record: bool = False, progress: Callable[[int], None] | None = None) -> TeamFlight:
    """Fly ``B`` scenarios of ``k`` passengers from ``slots`` to ``targets`` (both (B, k, n));
    ``separate``: with the separation barrier (False: each flies as if alone, the control run).
    ``progress`` is called with the ticks done every 50 ticks."""
    B, k, n = slots.shape
    N = B * k
    anchor = slots.reshape(N, n).astype(float)
    aim = targets.reshape(N, n).astype(float)
    model = TickModel(law=law, target=aim, obstacles=Obstacles.none(n), passenger_safety=safety,
                      carrier_safety=SafetyConfig(), planar_carrier=False)
    others = np.array([[j for j in range(k) if j != i] for i in range(k)], dtype=int)  # (k, k-1)
    e = np.zeros((N, n))
    u = np.zeros((N, n))
    done = np.zeros(N, dtype=bool)
    history = [(anchor.copy(), u.copy())] * (delay_ticks + 1)  # the states a bus would deliver, oldest first
    ages = np.full((N, k - 1), delay_ticks * dt_s)
    ticks = int(round(duration_s / dt_s))
    d = pair_distances(slots.astype(float))
    min_d = d.min(axis=-1)
    D = np.inf if safety.separation_m is None else safety.separation_m
    kept = np.minimum(d, D)  # what the barrier keeps, per pair
    shortfall = np.zeros(B)
    arrived = np.full(N, np.nan)
    infeasible = np.zeros(B, dtype=int)
    trace = np.empty((ticks, B)) if record else None
    for step in range(ticks):
        x_seen, v_seen = history[0]
        neighbours = None
        if separate:
            pos = x_seen.reshape(B, k, n)[:, others].reshape(N, k - 1, n)
            vel = v_seen.reshape(B, k, n)[:, others].reshape(N, k - 1, n)
            neighbours = Neighbours(pos, vel, ages)
        tick = passenger_tick(anchor, np.zeros(n), e, True, model, u, dt_s, neighbours=neighbours,
                              since_separation_s=step * dt_s)
        u = np.where(done[:, None], 0.0, tick.u)
        infeasible += (~np.asarray(tick.safety.feasible, dtype=bool) & ~done).reshape(B, k).any(axis=1)
        e = e + u * dt_s
        x = anchor + e
        history = history[1:] + [(x, u)]
        t = (step + 1) * dt_s
        reached = ~done & (norm(x - aim) <= arrival_radius_m)
        arrived[reached] = t
        done |= reached
        d = pair_distances(x.reshape(B, k, n))
        min_d = np.minimum(min_d, d.min(axis=-1))
        shortfall = np.maximum(shortfall, (kept - d).max(axis=-1))
        kept = np.maximum(kept, np.minimum(d, D))
        if trace is not None:
            trace[step] = d.min(axis=-1)
        if progress is not None and (step + 1) % 50 == 0:
            progress(50)
        if done.all():
            if trace is not None:
                trace[step + 1:] = d.min(axis=-1)
            break
    return TeamFlight(min_d, shortfall, arrived.reshape(B, k), infeasible, (anchor + e).reshape(B, k, n), trace)
