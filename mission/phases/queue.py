"""The recovery queue (pure): when several passengers of a team come home, one approaches the deck
at a time (docs/team.md, "The recovery queue").

Each passenger decides alone, from what the others share (:class:`mission.core.safety.Neighbours`:
their phase names, how long their recovery has run, their battery, their system id):

- **It waits while a neighbour is on the deck's approach** (APPROACH, its glide path and its
  descent, or DOCKED, holding contact): never two on the deck's approach at once, and nobody
  overtakes one already approaching.
- **It waits while the carrier serves a neighbour** (RIDING, TRANSIT, SEPARATED for the target the
  carrier announces: the carrier carries it to its target, repositions for it, or stops at its
  separation; a neighbour riding along for a later target does not hold it). The carrier's motion
  is about to change, and an approach flown then would meet a course that turns under it (the
  go-around of ``configs/team.toml`` before the queue). The carrier's recovery course begins once
  the served one has left (:mod:`mission.carrier.team`).
- **Among those waiting** (RETURNING, HOLDOFF, GO_AROUND) **the one that asked first goes first**
  (the longest recovery), **except that the battery decides when it must**: one with at most
  ``recovery.battery_reserve_pct + team.queue_battery_pct`` left must land, and goes before every
  one that need not, the lowest battery first. Two that asked within :data:`TIE_S` of each other
  go in the order of their system ids (a clock-free tie-break both sides agree on).

While it waits a passenger holds off at its *queue point* (:func:`queue_point`): its holdoff point
moved ``team.queue_distance_m`` farther back along the carrier's course and
``team.queue_height_m`` higher, and as much again for each neighbour waiting ahead of it
(:func:`place`), clear of the approaching one's glide path and of the queue point of the
one before it (the same offsets between two levels as between the first and a holdoff point,
:func:`mission.config.team.queue_clearance_m`); when its turn comes it
flies on to its holdoff point and settles there as alone. Both moves are the pursuit's
(:func:`mission.core.pursuit.pursue`): bounded speed and acceleration, so the commanded velocity
never jumps at the queue's switches. Waiting ``team.queue_timeout_s`` without a break falls back
(no deadlock: a neighbour that went silent in APPROACH is waited on, its last word standing, for
that long at most).

Frames: local NED [m]; times [s] on the controller's clock; battery [%].
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mission.core.docking import UP
from mission.core.records import replace
from mission.core.safety import Neighbours, SafetyConfig
from mission.phases.phase import Phase
from mission.phases.types import SAME_TARGET_M, MissionModel, MissionState, Observation, QueueModel, RecoveryState

#: A neighbour in one of these is on the deck's approach: nobody else begins one.
ON_APPROACH = frozenset({Phase.APPROACH.value, Phase.DOCKED.value})
#: A neighbour in one of these is served by the carrier, whose motion is about to change.
SERVED = frozenset({Phase.RIDING.value, Phase.TRANSIT.value, Phase.SEPARATED.value})
#: A neighbour in one of these waits for the deck (or asks for it): the queue's order decides.
WAITING = frozenset({Phase.RETURNING.value, Phase.HOLDOFF.value, Phase.GO_AROUND.value})
#: The recovery's phases whose reference keeps safety.passenger_separation_m from the other passengers ...
KEEP_APART = frozenset({Phase.RETURNING, Phase.HOLDOFF, Phase.GO_AROUND, Phase.FALLBACK})
#: ... and those on the deck's approach, which keep team.passenger_span_m (the deck's neighbouring slots are closer)
ON_DECK_APPROACH = frozenset({Phase.APPROACH, Phase.DOCKED})
#: A neighbour in one of these sits (or rides) on its slot: an obstacle of the deck's approach.
SEATED = frozenset({Phase.JOIN.value, Phase.RIDING.value, Phase.TRANSIT.value, Phase.DOCKED.value, Phase.HOME.value})
TIE_S = 0.1  # [s] two recoveries begun this close together count as asked at once (the system ids decide)


@dataclass(frozen=True)
class Claim:
    """One passenger's place in the queue: ``asked_s`` [s] how long ago its recovery began (now);
    ``battery_pct`` [%] (None: not known); ``must``: it must land (battery at or under the
    queue's threshold); ``rank``: its system id (None: unknown)."""

    asked_s: float
    battery_pct: float | None
    must: bool
    rank: int | None


def claim(asked_s: float, battery_pct: float | None, must_pct: float, rank: int | None) -> Claim:
    """The :class:`Claim` of a passenger whose recovery began ``asked_s`` [s] ago, with
    ``battery_pct`` [%] left; it must land at or under ``must_pct`` [%]."""
    return Claim(asked_s, battery_pct, battery_pct is not None and battery_pct <= must_pct, rank)


def goes_before(a: Claim, b: Claim) -> bool:
    """Whether ``a`` lands before ``b``: one that must before one that need not; of two that must,
    the lower battery; else the one that asked first (the longer recovery, beyond :data:`TIE_S`);
    else the lower system id. Never both ways for two distinct claims."""
    if a.must != b.must:
        return a.must
    if a.must and a.battery_pct is not None and b.battery_pct is not None and a.battery_pct != b.battery_pct:
        return a.battery_pct < b.battery_pct
    if abs(a.asked_s - b.asked_s) > TIE_S:
        return a.asked_s > b.asked_s
    big = 1 << 30
    return (a.rank if a.rank is not None else big) < (b.rank if b.rank is not None else big)


def _name(nb: Neighbours, j: int) -> str:
    return f"passenger {nb.ids[j]}" if nb.ids is not None else f"neighbour {j}"


def neighbour_claim(nb: Neighbours, j: int, must_pct: float) -> Claim:
    """Neighbour ``j``'s :class:`Claim` now: its shared recovery time moved on by its sample's age."""
    rec = nb.recovery_s[j] if nb.recovery_s is not None else None
    age = float(nb.age_s[j]) if nb.age_s is not None else 0.0
    battery = nb.battery_pct[j] if nb.battery_pct is not None else None
    return claim(-np.inf if rec is None else rec + age, battery, must_pct,
                 nb.ids[j] if nb.ids is not None else None)


def served(nb: Neighbours, j: int, announced_ned_m: np.ndarray | None) -> bool:
    """Whether the carrier serves neighbour ``j``: it is in a phase of :data:`SERVED` and the
    target it rides for is the one the carrier announces (``announced_ned_m`` [m] NED, within
    :data:`mission.phases.types.SAME_TARGET_M`). Either not known: served (the safe side)."""
    if nb.phases is None or nb.phases[j] not in SERVED:
        return False
    if announced_ned_m is None or nb.targets_ned_m is None:
        return True
    gap = np.asarray(nb.targets_ned_m[j], dtype=float) - np.asarray(announced_ned_m, dtype=float)[:3]
    return bool(np.linalg.norm(gap) <= SAME_TARGET_M)


def wait_reason(own: Claim, nb: Neighbours | None, must_pct: float,
                announced_ned_m: np.ndarray | None = None) -> str | None:
    """Why a passenger with ``own`` claim, returning or holding off, waits for its turn to
    approach (the first neighbour that holds it, in words), or None: its turn. ``nb``: the
    others as they shared their states (None, or no phases shared: alone, its turn);
    ``announced_ned_m`` [m] NED: the target the carrier announces (:func:`served`)."""
    if nb is None or nb.phases is None:
        return None
    for j, phase in enumerate(nb.phases):
        if phase in ON_APPROACH:
            return f"{_name(nb, j)} is on the deck's approach ({phase})"
    for j, phase in enumerate(nb.phases):
        if served(nb, j, announced_ned_m):
            return f"the carrier serves {_name(nb, j)} ({phase})"
    for j, phase in enumerate(nb.phases):
        if phase in WAITING:
            other = neighbour_claim(nb, j, must_pct)
            if goes_before(other, own):
                why = "must land first" if other.must and not own.must else (
                    "has less battery" if other.must else "asked first")
                return f"{_name(nb, j)} {why} ({phase})"
    return None


def place(own: Claim, nb: Neighbours | None, must_pct: float) -> int:
    """Its place among those waiting: how many neighbours wait ahead of it (:data:`WAITING`,
    :func:`goes_before`); 0: it is the next to go."""
    if nb is None or nb.phases is None:
        return 0
    return sum(phase in WAITING and goes_before(neighbour_claim(nb, j, must_pct), own) for j, phase in enumerate(nb.phases))


def yield_reason(own: Claim, nb: Neighbours | None, must_pct: float) -> str | None:
    """Why a passenger already on its glide path (APPROACH, not descending yet) gives way, or
    None: a neighbour holding contact (DOCKED), or one on its own approach that goes before it
    (two began at once: their states crossed on the way)."""
    if nb is None or nb.phases is None:
        return None
    for j, phase in enumerate(nb.phases):
        if phase == Phase.DOCKED.value:
            return f"{_name(nb, j)} is docking ({phase})"
        if phase == Phase.APPROACH.value and goes_before(neighbour_claim(nb, j, must_pct), own):
            return f"{_name(nb, j)} approaches too and goes first"
    return None


def queue_point(holdoff_ned_m: np.ndarray, course_unit: np.ndarray, distance_m: float, height_m: float) -> np.ndarray:
    """[m] NED where a waiting passenger holds off: its holdoff point ``holdoff_ned_m`` moved
    ``distance_m`` [m] back along the carrier's course ``course_unit`` and ``height_m`` [m] up."""
    return np.asarray(holdoff_ned_m, dtype=float) - distance_m * np.asarray(course_unit, dtype=float) + height_m * UP


def apart(state: MissionState, obs: Observation, m: MissionModel) -> tuple[SafetyConfig, Neighbours | None]:
    """The reference filter's configuration and the neighbours it keeps apart from in this phase:
    ``safety.passenger_separation_m + safety.margin_m`` in the air (:data:`KEEP_APART`), ``team.passenger_span_m``
    on the deck's approach (:data:`ON_DECK_APPROACH`: the deck's other passengers as obstacles, its
    neighbouring slots closer than the separation), none otherwise (riding the dock point; or no
    neighbour, or no queue: the filter as alone). A pair already closer is held at its distance,
    never pushed apart (:func:`mission.core.safety.neighbour_rows`)."""
    base = m.tick.passenger_safety
    q = m.queue
    if q is None or obs.neighbours is None or base.separation_m is None:
        return base, None
    nb: Neighbours | None = obs.neighbours
    if state.phase in KEEP_APART:
        distance = q.separation_m
        nb = seated_at_span(obs.neighbours, obs, q)
    elif state.phase in ON_DECK_APPROACH:
        distance = q.deck_clearance_m
        nb = on_deck(obs.neighbours, obs)
        if nb is None:
            return base, None
    else:
        return base, None
    key = ("recovery_separation", distance)
    cfg = base._cache.get(key)
    if cfg is None:
        cfg = base._cache[key] = replace(base, separation_m=distance)
    return cfg, nb


def seated_at_span(nb: Neighbours, obs: Observation, q: QueueModel) -> Neighbours:
    """The neighbours as the recovery's air phases (:data:`KEEP_APART`) keep apart from them: those
    in the air at ``q.separation_m``, those seated on the deck (:data:`SEATED`) as the deck's
    obstacles (:func:`on_deck`: at ``q.deck_clearance_m``, moving with the deck). A go-around
    climbs from the deck's approach, its goal above its own slot 1.1-1.5 m from a neighbour's:
    kept 3.5 m from the seated ones, its reference circled that goal and never reached it, and
    the recovery fell back after recovery.timeout_s (team Monte-Carlo, docs/team.md). ``nb``
    itself when no phase is shared or none is seated."""
    if nb.phases is None:
        return nb
    seated = np.array([p in SEATED for p in nb.phases], dtype=bool)
    if not seated.any():
        return nb
    v = np.asarray(obs.carrier.velocity_ned_m_s if obs.carrier is not None else np.zeros(3), dtype=float)
    vel = np.where(seated[:, None], v[None, :], np.asarray(nb.velocities_m_s, dtype=float))
    return replace(nb, velocities_m_s=vel, distance_m=np.where(seated, q.deck_clearance_m, q.separation_m), on_deck=seated)


def on_deck(nb: Neighbours, obs: Observation) -> Neighbours | None:
    """The neighbours on the deck (:data:`SEATED`; all when no phase is shared) as obstacles of an
    approach: where they report themselves, moving with the deck (the carrier's velocity, not their
    own reported one: PX4's velocity estimate errs by ~0.25 m/s, and a seated neighbour moves with
    the deck), each kept on a sphere (``Neighbours.on_deck``); None: none."""
    keep = np.ones(len(nb), dtype=bool) if nb.phases is None else np.array([p in SEATED for p in nb.phases], dtype=bool)
    if not keep.any():
        return None
    v = obs.carrier.velocity_ned_m_s if obs.carrier is not None else np.zeros(3)
    pos = np.asarray(nb.positions_m, dtype=float)[keep]
    age = None if nb.age_s is None else np.asarray(nb.age_s, dtype=float)[keep]
    return Neighbours(pos, np.tile(np.asarray(v, dtype=float), (len(pos), 1)), age, on_deck=np.ones(len(pos), dtype=bool))


def turn(obs: Observation, m: MissionModel, rec: RecoveryState
         ) -> tuple[RecoveryState, str | None, str | None, tuple[str, ...]]:
    """The queue's word this tick (:mod:`mission.phases.queue`): ``rec`` with its waiting time,
    why it waits (None: its turn), why it falls back (it waited ``team.queue_timeout_s``; None:
    it does not) and the events (it starts waiting or waits for another reason; its turn came)."""
    q = m.queue
    if q is None:
        return rec, None, None, ()
    v = obs.vehicle
    own = claim(obs.t_s - rec.started_s, None if v is None else v.battery_pct, q.must_pct, q.rank)
    why = wait_reason(own, obs.neighbours, q.must_pct, obs.carrier_target_ned_m)
    if why is None:
        if rec.queued_since_s is None:
            return rec, None, None, ()
        return replace(rec, queued_since_s=None, queued_for=None, queue_place=0), None, None, (
            "its turn: on to the holdoff point",)
    since = rec.queued_since_s if rec.queued_since_s is not None else obs.t_s
    events = (f"waits its turn: {why}",) if why != rec.queued_for else ()
    rec = replace(rec, queued_since_s=since, queued_for=why, queue_place=1 + place(own, obs.neighbours, q.must_pct))
    if obs.t_s - since > q.timeout_s:
        return rec, why, f"waited its turn for team.queue_timeout_s = {q.timeout_s:g} s ({why})", events
    return rec, why, None, events


def holdoff_goal(h: np.ndarray, rec: RecoveryState, m: MissionModel, waits: str | None) -> np.ndarray:
    """Where the passenger holds off: its holdoff point ``h`` [m] NED, or while it waits its queue
    point of its place (``rec.queue_place``: one level per neighbour ahead of it)."""
    if waits is None or m.queue is None:
        return h
    k = rec.queue_place
    return queue_point(h, rec.course, k * m.queue.distance_m, k * m.queue.height_m)
