"""One carrier, several passengers: ``[team]``, the carrier's dock slots and the passengers bound to
them (docs/team.md). Part of the schema in :mod:`mission.config.schema`; pure.

Without ``[team]`` a file describes one passenger exactly as before: it rides
``mission.dock_offset_ned_m``, flies ``mavlink.target_system``, and visits every target of
``scenario.targets``. With it, each of those facts is the team's, declared once: a passenger rides
its slot (``team.slots[k].offset_ned_m``), flies its own system id and visits its own targets
(indices into ``scenario.targets``, whose order stays the mission's). The file may then not state
``mission.dock_offset_ned_m`` or ``mavlink.target_system``; one passenger's process flies the
single-passenger configuration :func:`passenger_data` derives (``marsupial run --passenger NAME``).

Frames: slot offsets are local NED [m] (z down) from the carrier's reported position, as
``mission.dock_offset_ned_m``; "horizontal" is their first two components.
"""
from __future__ import annotations

import math
from typing import Annotated, Any

from pydantic import Field

from mission.config.fields import Section
from mission.config.scenario import MAX_TARGETS
from mission.config.vision import APRILTAG_36H11_TAGS
from mission.errors import ConfigError

MAX_TEAM = 16  # slots, passengers
NAME = r"^[A-Za-z0-9_\-]+$"
#: The single-passenger fields a team declares itself (the slot's offset, the passenger's system id).
SINGLE_FIELDS = {"mission.dock_offset_ned_m": "team.slots[].offset_ned_m",
                 "mavlink.target_system": "team.passengers[].system_id",
                 "vision.marker_offset_ned_m": "team.slots[].marker_offset_ned_m"}
#: A slot's own marker fields and the passenger's ``[vision]`` field each sets (unset: vision's).
SLOT_MARKER_FIELDS = ("tag_id", "small_tag_id", "marker_offset_ned_m")


class SlotSection(Section):
    """A dock slot on the carrier's deck."""

    name: str = Field(pattern=NAME, max_length=64, description="[-] the slot's name (team.passengers[].slot gives it)")
    offset_ned_m: list[Annotated[float, Field(ge=-100, le=100)]] = Field(
        description=("[m] NED offset of the slot's dock point from the carrier's reported position (its passenger "
                     "rides and docks there, as mission.dock_offset_ned_m without a team)"))
    tag_id: int | None = Field(None, ge=0, lt=APRILTAG_36H11_TAGS,
        description=("[-] the AprilTag 36h11 id of the slot's marker's big (or only) tag, what its passenger's "
                     "detector looks for (its vision.tag_id); unset: vision.tag_id. Slots of a team flying the marker "
                     "feed need ids of their own, or a passenger would take another slot's marker for its own"))
    small_tag_id: int | None = Field(None, ge=0, lt=APRILTAG_36H11_TAGS,
        description="[-] ... and of its bundle's small tag (its vision.small_tag_id); unset: vision.small_tag_id")
    marker_offset_ned_m: list[Annotated[float, Field(ge=-100, le=100)]] | None = Field(None,
        description=("[m] NED offset of the slot's marker's centre from the carrier's reported position (its "
                     "passenger's vision.marker_offset_ned_m); unset: at the slot's dock point. A hover ride rides over "
                     "the deck: set the deck under the dock point, e.g. [0, y, 0] for a dock point [0, y, -1.5]"))


class TeamPassengerSection(Section):
    """A passenger of the team."""

    name: str = Field(pattern=NAME, max_length=64, description="[-] the passenger's name (`marsupial run --passenger NAME`)")
    system_id: int = Field(ge=1, le=255, description="[-] its vehicle's MAVLink system id (its mavlink.target_system)")
    slot: str = Field(max_length=64, description="[-] the name of its slot in team.slots")
    targets: list[int] = Field(max_length=MAX_TARGETS,
        description=("[-] its targets, indices into scenario.targets (0 the first; scenario.target alone is 0), in the "
                     "mission's order: one target is a list of one"))


class TeamSection(Section):
    """``[team]``: the carrier's dock slots and the passengers bound to them (leave out: one passenger)."""

    passenger_span_m: float = Field(0.8, gt=0, le=10,
        description=("[m] a passenger's width, propeller tip to tip: two slots' dock points must be this plus twice "
                     "recovery.contact_radius_m apart horizontally (docked anywhere contact allows, they do not touch)"))
    queue_distance_m: float = Field(3.0, ge=0, le=100,
        description=("[m] the recovery queue (docs/team.md): a passenger waiting for its turn to approach holds off this "
                     "much farther behind its holdoff point, along the carrier's course, per passenger ahead of it"))
    queue_height_m: float = Field(3.5, ge=0, le=100,
        description=("[m] ... and this much higher than its holdoff point (both per passenger ahead of it): at least "
                     "safety.passenger_separation_m + safety.margin_m from every other slot's approach (its holdoff point, "
                     "glide path and descent) and queue point, whatever the course"))
    queue_timeout_s: float = Field(120.0, gt=0, le=3600,
        description=("[s] a passenger that has waited its turn this long without a break falls back "
                     "(recovery.fallback): no deadlock"))
    queue_battery_pct: float = Field(10.0, ge=0, le=100,
        description=("[%] a returning passenger with at most recovery.battery_reserve_pct + this left must land: it goes "
                     "before every one that need not, the lowest battery first; the others go in the order they asked"))
    slots: list[SlotSection] = Field([], max_length=MAX_TEAM,
        description="[-] list of `{ name, offset_ned_m = [m] }`: the carrier's dock slots")
    passengers: list[TeamPassengerSection] = Field([], max_length=MAX_TEAM,
        description="[-] list of `{ name, system_id, slot, targets = [index] }`: one entry per passenger, one slot each")

    @property
    def given(self) -> bool:
        """Whether the file declared a team: any slot or passenger. An empty ``[team]`` (or a dump of a
        one-passenger configuration, which writes the empty lists) is one passenger, as without it."""
        return bool(self.slots or self.passengers)

    def slot_index(self, name: str) -> int:
        """The index in :attr:`slots` of the slot called ``name`` (the name is checked at load)."""
        return next(k for k, slot in enumerate(self.slots) if slot.name == name)

    def owners(self, n_targets: int) -> list[int]:
        """For each of the mission's ``n_targets`` targets, the index of the passenger that flies to it."""
        owner = [0] * n_targets
        for i, p in enumerate(self.passengers):
            for t in p.targets:
                owner[t] = i
        return owner


def dock_points(team: TeamSection | None, single_offset_ned_m: list[float],
                n_targets: int) -> tuple[list[tuple[str, list[float]]], list[list[float]]]:
    """The dock points [m] NED from the carrier's reported position, each with the field that
    declares it (``mission.dock_offset_ned_m`` = ``single_offset_ned_m`` without a ``team``, else
    every slot), and for each of the ``n_targets`` targets the one its passenger leaves from."""
    if team is None:
        return [("mission.dock_offset_ned_m", single_offset_ned_m)], [single_offset_ned_m] * n_targets
    docks = [(f"team.slots[{k}].offset_ned_m", list(slot.offset_ned_m)) for k, slot in enumerate(team.slots)]
    return docks, [list(team.slots[team.slot_index(team.passengers[i].slot)].offset_ned_m) for i in team.owners(n_targets)]


def min_slot_spacing_m(team: TeamSection, contact_radius_m: float) -> float:
    """[m] the least horizontal distance between two slots' dock points: a passenger counts as docked
    anywhere within ``contact_radius_m`` [m] (recovery.contact_radius_m) of its slot, so two docked
    neighbours may each sit that much towards the other, and still their spans must not touch."""
    return team.passenger_span_m + 2.0 * contact_radius_m


def check_team(team: TeamSection, *, n_targets: int, target_field: str, contact_radius_m: float,
               stated: dict[str, Any], carrier_system_id: int | None) -> None:
    """Refuse a team that is not one passenger per slot and per target (raises :class:`ConfigError`
    naming the field). ``n_targets``: the mission's targets; ``target_field``: how the file named
    them (``scenario.targets``, or ``scenario.target`` alone); ``stated``: the dotted fields the file
    set, with their values (a field of :data:`SINGLE_FIELDS` is the team's); ``carrier_system_id``: the carrier vehicle's
    MAVLink system id, if it has one."""
    for field, instead in SINGLE_FIELDS.items():
        if field in stated:
            raise ConfigError(field, stated[field], f"with a [team] each passenger's comes from {instead}: leave it out "
                              "(one fact, declared once)")
    if not team.passengers:
        raise ConfigError("team.passengers", [], "a [team] needs at least one passenger")
    _check_slots(team, contact_radius_m)
    names = [s.name for s in team.slots]
    for i, p in enumerate(team.passengers):
        field = f"team.passengers[{i}]"
        earlier = team.passengers[:i]
        if p.name in [q.name for q in earlier]:
            raise ConfigError(f"{field}.name", p.name, "another passenger has this name")
        same = [j for j, q in enumerate(earlier) if q.system_id == p.system_id]
        if same:
            raise ConfigError(f"{field}.system_id", p.system_id, f"also team.passengers[{same[0]}]'s "
                              f"({earlier[same[0]].name!r}): every vehicle needs its own MAVLink system id")
        if p.system_id == carrier_system_id:
            raise ConfigError(f"{field}.system_id", p.system_id, "also the carrier's (carrier.mavlink.target_system)")
        if p.slot not in names:
            raise ConfigError(f"{field}.slot", p.slot, f"no such slot in team.slots ({', '.join(names) or 'none'})")
        taken = [j for j, q in enumerate(earlier) if q.slot == p.slot]
        if taken:
            raise ConfigError(f"{field}.slot", p.slot, f"also team.passengers[{taken[0]}]'s ({earlier[taken[0]].name!r}): "
                              "one passenger per slot")
        if not p.targets:
            raise ConfigError(f"{field}.targets", [], "a passenger with no target: give it at least one index into "
                              f"{target_field}")
        for j, t in enumerate(p.targets):
            if not 0 <= t < n_targets:
                raise ConfigError(f"{field}.targets[{j}]", t, f"no such target: {target_field} has {n_targets} "
                                  f"(indices 0..{n_targets - 1})")
            if j and t <= p.targets[j - 1]:
                raise ConfigError(f"{field}.targets[{j}]", t, f"after {p.targets[j - 1]}: a passenger's targets go in "
                                  f"the mission's order, the order of {target_field} (docs/team.md)")
            owner = [k for k, q in enumerate(earlier) if t in q.targets]
            if owner:
                raise ConfigError(f"{field}.targets[{j}]", t, f"also team.passengers[{owner[0]}]'s "
                                  f"({earlier[owner[0]].name!r}): one passenger per target")
    served = {t for p in team.passengers for t in p.targets}
    for k in range(n_targets):
        if k not in served:
            name = f"{target_field}[{k}]" if target_field == "scenario.targets" else target_field
            raise ConfigError(name, k, "no passenger of team.passengers flies to it: list it in one's targets")


QUEUE_HEADINGS = 72  # the carrier's courses (every 5 deg) over which the queue's clearance is checked


def queue_clearance_m(team: TeamSection, holdoff_distance_m: float, holdoff_height_m: float,
                      decision_height_m: float, vertical_ratio: float = 1.0) -> float:
    """[m] the least distance, over every course of the carrier (:data:`QUEUE_HEADINGS`) and every
    pair of slots, from one slot's queue point (its holdoff point ``team.queue_distance_m`` farther
    back along the course and ``team.queue_height_m`` higher; :mod:`mission.phases.queue`) to the
    other slot's approach: its holdoff point (``holdoff_distance_m`` [m] behind and
    ``holdoff_height_m`` [m] above its dock point), the glide path to its gate
    (``decision_height_m`` [m] above the dock point) and the descent onto it. inf: fewer than two slots.
    Measured as the pairwise barrier measures (:func:`mission.core.safety.neighbour_rows`): heights
    divided by ``vertical_ratio`` (safety.passenger_separation_vertical_m over passenger_separation_m)."""
    import numpy as np

    best = math.inf
    squash = np.array([1.0, 1.0, 1.0 / vertical_ratio])  # the barrier's metric: a linear map, segments stay segments
    docks = [np.asarray(slot.offset_ned_m, dtype=float) * squash for slot in team.slots]
    up = np.array([0.0, 0.0, -1.0]) * squash
    for k in range(QUEUE_HEADINGS):
        a = 2.0 * math.pi * k / QUEUE_HEADINGS
        c = np.array([math.cos(a), math.sin(a), 0.0])
        for i, wait in enumerate(docks):
            q = wait - (holdoff_distance_m + team.queue_distance_m) * c + (holdoff_height_m + team.queue_height_m) * up
            for j, dock in enumerate(docks):
                if i != j:
                    h, gate = dock - holdoff_distance_m * c + holdoff_height_m * up, dock + decision_height_m * up
                    best = min(best, _to_segment(q, h, gate), _to_segment(q, gate, dock))
    return best


def _to_segment(p, a, b) -> float:  # type: ignore[no-untyped-def]
    """[m] the distance from point ``p`` to the segment ``a``-``b`` (numpy arrays)."""
    import numpy as np

    ab = b - a
    s = float(np.clip(np.dot(p - a, ab) / max(float(np.dot(ab, ab)), 1e-300), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + s * ab)))


def check_queue(team: TeamSection, separation_m: float, recovery: Any, vertical_ratio: float = 1.0) -> None:
    """Refuse queue points closer than ``separation_m`` [m] (safety.passenger_separation_m +
    safety.margin_m, what the recovery keeps; in the barrier's metric, ``vertical_ratio``) to
    another slot's approach on some course (:func:`queue_clearance_m`, the geometry of the
    ``[recovery]`` section ``recovery``), naming team.queue_height_m."""
    r = recovery
    holdoff_height_m = r.decision_height_m + r.holdoff_distance_m * math.tan(math.radians(r.glide_angle_deg))
    clear = queue_clearance_m(team, r.holdoff_distance_m, holdoff_height_m, r.decision_height_m, vertical_ratio)
    if clear < separation_m - 1e-6:
        raise ConfigError("team.queue_height_m", team.queue_height_m,
                          f"a passenger waiting its turn would hold off {clear:.2f} m from another slot's approach on "
                          f"some course, under safety.passenger_separation_m + safety.margin_m = {separation_m:g} m (heights "
                          "divided by safety.passenger_separation_vertical_m / passenger_separation_m): raise it (or "
                          "team.queue_distance_m)")


def _closest_slots(team: TeamSection, spacing_m: float) -> tuple[int, int, float] | None:
    """The first two slots (``k``, an earlier ``j``, their distance [m]) whose dock points are
    closer than ``spacing_m`` [m] horizontally; None: none are."""
    for k, slot in enumerate(team.slots):
        for j, other in enumerate(team.slots[:k]):
            apart = math.dist(slot.offset_ned_m[:2], other.offset_ned_m[:2])
            if apart < spacing_m - 1e-9:
                return k, j, apart
    return None


def _check_slots(team: TeamSection, contact_radius_m: float) -> None:
    for k, slot in enumerate(team.slots):
        field = f"team.slots[{k}]"
        if len(slot.offset_ned_m) != 3:
            raise ConfigError(f"{field}.offset_ned_m", slot.offset_ned_m, "must have 3 components")
        if slot.marker_offset_ned_m is not None and len(slot.marker_offset_ned_m) != 3:
            raise ConfigError(f"{field}.marker_offset_ned_m", slot.marker_offset_ned_m, "must have 3 components")
        for j, other in enumerate(team.slots[:k]):
            if other.name == slot.name:
                raise ConfigError(f"{field}.name", slot.name, f"also team.slots[{j}]'s name")
    spacing = min_slot_spacing_m(team, contact_radius_m)
    if (close := _closest_slots(team, spacing)) is not None:
        k, j, apart = close
        raise ConfigError(f"team.slots[{k}].offset_ned_m", team.slots[k].offset_ned_m,
                          f"overlaps team.slots[{j}] ({team.slots[j].name!r}): {apart:.2f} m from it horizontally, "
                          f"under team.passenger_span_m + 2 recovery.contact_radius_m = {spacing:g} m "
                          "(two passengers docked within recovery.contact_radius_m of these slots could touch)")


def check_hover_slots(team: TeamSection, ride: str, margin_m: float) -> None:
    """Refuse a team that rides hovering (``ride`` ``"hover"``, mission.ride) on slots its riding
    passengers could touch on (raises :class:`ConfigError` naming the nearer slot's offset): a
    rider hovers where its estimate puts it, so two riding neighbours each keep ``margin_m`` [m]
    (safety.margin_m, the clearance kept from every obstacle) from the other's span: ``team.passenger_span_m
    + 2 margin_m`` between their slots' dock points horizontally, where a docked one needs only the
    span and the contact radius (:func:`min_slot_spacing_m`). Checked by the commands that fly a
    team (``run``, ``carrier``, ``demo``); the in-process simulation flies a deck team hovering on
    its deck slots (:func:`sim.batch.team_mission.hovering`) and is not refused."""
    spacing = team.passenger_span_m + 2.0 * margin_m
    if ride != "hover" or (close := _closest_slots(team, spacing)) is None:
        return
    k, j, apart = close
    raise ConfigError(f"team.slots[{k}].offset_ned_m", team.slots[k].offset_ned_m,
                      f"{apart:.2f} m from team.slots[{j}] ({team.slots[j].name!r}) horizontally: a team riding "
                      f"hovering needs team.passenger_span_m + 2 safety.margin_m = {spacing:g} m (each rider "
                      "hovers where its estimate puts it)")


def passenger_data(data: dict[str, Any], team: TeamSection, targets: list[list[float]], i: int) -> dict[str, Any]:
    """The single-passenger configuration (a nested dict, as a file gives it) of passenger ``i`` of
    ``team`` in the team's configuration ``data`` whose mission's targets are ``targets`` [m]: no
    ``[team]``, ``mission.dock_offset_ned_m`` its slot's offset, ``mavlink.target_system`` its system
    id, and its own targets (``scenario.target`` for one, ``scenario.targets`` for several); the
    scalars of ``[team]`` the file stated (its span, its queue) stay, without slots or passengers."""
    p = team.passengers[i]
    out = {key: dict(value) if isinstance(value, dict) else value for key, value in data.items() if key != "team"}
    shared = {key: value for key, value in data.get("team", {}).items() if key not in ("slots", "passengers")}
    if shared:  # the team's own tuning (the span, the queue): every passenger's, declared once in [team]
        out["team"] = shared
    scenario = out.setdefault("scenario", {})
    scenario.pop("target", None)
    scenario.pop("targets", None)
    own = [list(targets[t]) for t in p.targets]
    scenario.update({"target": own[0]} if len(own) == 1 else {"targets": own})
    slot = team.slots[team.slot_index(p.slot)]
    out.setdefault("mission", {})["dock_offset_ned_m"] = list(slot.offset_ned_m)
    out.setdefault("mavlink", {})["target_system"] = p.system_id
    marker = {name: getattr(slot, name) for name in SLOT_MARKER_FIELDS if getattr(slot, name) is not None}
    if marker:  # the slot's own marker: what its passenger's detector looks for, and where
        out["vision"] = {**out.get("vision", {}), **marker}
    return out


def slot_tag_ids(team: TeamSection, tag_id: int, small_tag_id: int, bundle: bool) -> list[tuple[int, ...]]:
    """The tag ids of each slot's marker, in :attr:`TeamSection.slots`' order: its own
    (``team.slots[k].tag_id``, ``small_tag_id``) or, unset, ``[vision]``'s ``tag_id`` and
    ``small_tag_id``; the small one only in a ``bundle``."""
    return [(slot.tag_id if slot.tag_id is not None else tag_id,
             *((slot.small_tag_id if slot.small_tag_id is not None else small_tag_id,) if bundle else ()))
            for slot in team.slots]


def check_slot_markers(team: TeamSection, tag_id: int, small_tag_id: int, bundle: bool) -> None:
    """Refuse two slots whose markers share a tag id (raises :class:`ConfigError` naming the later
    slot's ``tag_id``, or ``small_tag_id`` when only that one is shared): each passenger's detector
    keeps only its own slot's ids (:func:`slot_tag_ids`), so a shared one would let it take another
    slot's marker for its own. For a team flying the marker feed (``mission.feeds``)."""
    ids = slot_tag_ids(team, tag_id, small_tag_id, bundle)
    for k, own in enumerate(ids):
        for j, other in enumerate(ids[:k]):
            shared = sorted(set(own) & set(other))
            if shared:
                name = "tag_id" if own[0] in shared else "small_tag_id"
                raise ConfigError(f"team.slots[{k}].{name}", getattr(team.slots[k], name),
                                  f"tag id {shared[0]} is also team.slots[{j}]'s ({team.slots[j].name!r}) marker's: "
                                  "each slot's marker needs ids of its own (team.slots[].tag_id, small_tag_id; unset: "
                                  "vision.tag_id, small_tag_id), or its passenger takes the other slot's for its own")


def as_team_error(error: ConfigError, team: TeamSection, i: int, target_field: str) -> ConfigError:
    """``error`` of passenger ``i``'s derived configuration (:func:`passenger_data`) naming the team
    file's field: its slot's offset, its system id, the mission's index of its target; any other
    field as it is, the passenger named in the rule."""
    p = team.passengers[i]
    field = error.field
    k = team.slot_index(p.slot)
    named = {"mission.dock_offset_ned_m": f"team.slots[{k}].offset_ned_m",
             "mavlink.target_system": f"team.passengers[{i}].system_id"}
    named |= {f"vision.{name}": f"team.slots[{k}].{name}" for name in SLOT_MARKER_FIELDS
              if getattr(team.slots[k], name) is not None}
    for own, index in [("scenario.target", p.targets[0])] + [(f"scenario.targets[{j}]", t) for j, t in enumerate(p.targets)]:
        named[own] = f"{target_field}[{index}]" if target_field == "scenario.targets" else target_field
    for old, new in named.items():
        if field == old or field.startswith((old + "[", old + ".")):
            return ConfigError(new + field.removeprefix(old), error.value, error.rule)
    return ConfigError(field, error.value, f"{error.rule} (as team.passengers[{i}] {p.name!r} flies it)")
