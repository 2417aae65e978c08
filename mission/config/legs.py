"""The checks of a mission with several targets (``scenario.targets``), at load: every leg can
start where the paper's Assumption 1 holds (|e_tc| >= eta > b c), or the file is refused naming
the field (pure; part of :meth:`mission.config.schema.Config._cross_fields`).

Leg k >= 1 starts where the passenger docked after leg k - 1, which no static check knows (the
recovery's course and its timing decide it). There the carrier first drives straight out from
``targets[k]`` until its dock point is ``R = b c + mission.leg_start_margin_m`` (and
:data:`REPOSITION_SPARE_M`) from it (TRANSIT), every target's P3 guard and
the obstacles' CBF acting on that drive: the guard and the CBF cut the inward part of the
command, so the carrier slides along a keep-out circle or an obstacle rather than stopping. What
is refused is what makes the drive-out impossible wherever the carrier docked:

- a target inside another's keep-out (horizontally within ``b c`` of it): wherever the carrier
  serves one it is inside the other's keep-out;
- the carrier starting inside a later target's keep-out (P3 broken from the start);
- a target inside an obstacle, or too high above a planar carrier's plane (it never comes within
  ``b c`` of it);
- no place to start the leg from: every point of the leg-start circle (the dock point's
  horizontal distance from ``targets[k]`` at which it is ``R`` from it; the shipped dock offsets
  are vertical, so the carrier stands there too) lies inside another target's P3 circle (where
  the carrier is ``b c - carrier.p3_margin_m`` from it, its height above a planar carrier's plane
  counted as the guard counts it; the carrier never enters it) or an obstacle (radius +
  ``safety.margin_m``, which its filter keeps it out of).

Frames: horizontal = the first two components (local NED north, east; a 2D scenario's plane) [m].
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from mission.errors import ConfigError

if TYPE_CHECKING:
    from mission.config.scenario import ScenarioSection

REPOSITION_SPARE_M = 0.5  # [m] the carrier's repositioning goes this much beyond the next leg's start distance


def _h(a: list[float], b: list[float]) -> float:
    """Horizontal distance [m] between two points."""
    return math.dist(a[:2], b[:2])


def _across(radius_m: float, height_m: float) -> float:
    """The horizontal radius [m] of a sphere of ``radius_m`` [m] at ``height_m`` [m] from its centre."""
    return math.sqrt(max(radius_m ** 2 - height_m ** 2, 0.0))


def covered_circle(center: list[float], radius_m: float, discs: list[tuple[list[float], float]]) -> bool:
    """Whether the circle of ``radius_m`` [m] round ``center`` (horizontal) lies wholly inside the
    union of the closed ``discs`` ((centre, radius [m]), horizontal)."""
    arcs: list[tuple[float, float]] = []  # covered arcs [rad], each within [-pi, pi] after splitting
    for c, rho in discs:
        d = _h(center, c)
        if d + radius_m <= rho:
            return True  # the whole circle inside one disc
        if d >= radius_m + rho or d + rho <= radius_m or d == 0.0:
            continue  # apart, or the disc inside the circle: no point of the circle covered
        half = math.acos(max(-1.0, min(1.0, (radius_m ** 2 + d ** 2 - rho ** 2) / (2.0 * radius_m * d))))
        mid = math.atan2(c[1] - center[1], c[0] - center[0])
        lo, hi = mid - half, mid + half
        if lo < -math.pi:
            arcs += [(lo + 2 * math.pi, math.pi), (-math.pi, hi)]
        elif hi > math.pi:
            arcs += [(lo, math.pi), (-math.pi, hi - 2 * math.pi)]
        else:
            arcs.append((lo, hi))
    reach = -math.pi
    for lo, hi in sorted(arcs):
        if lo > reach + 1e-12:
            return False  # a gap: a point of the circle outside every disc
        reach = max(reach, hi)
    return reach >= math.pi - 1e-12


def check_legs(s: ScenarioSection, *, final_action: str, bc_m: float, leg_start_margin_m: float,
               dock_offsets_ned_m: list[list[float]], p3_margin_m: float, safety_margin_m: float) -> None:
    """Refuse targets of scenario ``s`` that leave a leg no start under Assumption 1 (the rules of
    the module docstring), given the fields of the other sections they depend on (each named as
    its field: ``mission.final_action``, ``b c`` [m], ``mission.leg_start_margin_m`` [m],
    ``carrier.p3_margin_m`` [m], ``safety.margin_m`` [m]) and each leg's dock offset [m] NED (the
    passenger's: ``mission.dock_offset_ned_m``, or with a team its slot's); raises
    :class:`ConfigError` naming the field to change."""
    legs = s.legs()
    if len(legs) > 1 and final_action != "return":
        raise ConfigError("mission.final_action", final_action,
                          f"must be \"return\" with {len(legs)} scenario.targets (the passenger comes home between them)")
    for j, later in enumerate(legs[1:], start=1):
        for i, earlier in enumerate(legs[:j]):
            if _h(later, earlier) <= bc_m:
                raise ConfigError(f"scenario.targets[{j}]", later, f"inside the keep-out of scenario.targets[{i}] "
                                  f"({_h(later, earlier):.2f} m from it horizontally, b*c = {bc_m:g} m)")
    for k, target in enumerate(legs[1:], start=1):
        if _h(s.carrier_start, target) <= bc_m:
            raise ConfigError("scenario.carrier_start", s.carrier_start, f"inside the keep-out of scenario.targets[{k}] "
                              f"({_h(s.carrier_start, target):.2f} m from it horizontally, b*c = {bc_m:g} m)")
        for i, ob in enumerate(s.obstacles):
            if math.dist(target, ob.center) <= ob.radius:
                raise ConfigError(f"scenario.targets[{k}]", target, f"inside scenario.obstacles[{i}] "
                                  f"(center {ob.center}, radius {ob.radius:g} m)")
    if len(legs) < 2:
        return
    dim = s.dim
    ground = s.carrier_start[2] if dim == 3 else 0.0
    start_m = bc_m + leg_start_margin_m + REPOSITION_SPARE_M
    guard_m = bc_m - p3_margin_m
    for k, target in enumerate(legs[1:], start=1):
        # the dock point's height below or above the target: the leg may start nearer horizontally
        height = abs(target[2] - (ground + dock_offsets_ned_m[k][2])) if dim == 3 and s.planar_carrier else 0.0
        if dim == 3 and s.planar_carrier and abs(target[2] - ground) > bc_m:
            raise ConfigError(f"scenario.targets[{k}]", target, f"{abs(target[2] - ground):.2f} m above the carrier's "
                              f"plane, more than b*c = {bc_m:g} m: the carrier can never come within b*c of it")
        if height >= start_m:
            continue  # Assumption 1 holds wherever the carrier stands
        ring_m = math.sqrt(start_m ** 2 - height ** 2)
        discs = [(other, _across(guard_m, other[2] - ground if dim == 3 and s.planar_carrier else 0.0))
                 for i, other in enumerate(legs) if i != k]
        discs += [(list(ob.center), ob.radius + safety_margin_m) for ob in s.obstacles]
        if covered_circle(target, ring_m, discs):
            raise ConfigError(f"scenario.targets[{k}]", target, f"no place to start its leg: every point {ring_m:.2f} m "
                              f"from it horizontally (the dock point b*c + mission.leg_start_margin_m + {REPOSITION_SPARE_M:g} m "
                              f"= {start_m:g} m from it, the paper's Assumption 1) is inside another target's keep-out "
                              "or an obstacle, so the carrier cannot drive out to where the leg may start")


def first_target_named(error: ConfigError, data: dict[str, Any]) -> ConfigError:
    """``error`` naming ``scenario.targets[0]`` instead of ``scenario.target`` when the file gave
    only ``scenario.targets`` (``target`` is then a copy of its first entry, a field the user never wrote)."""
    scenario = data.get("scenario")
    field = error.field
    if not (isinstance(scenario, dict) and "targets" in scenario and "target" not in scenario):
        return error
    if field != "scenario.target" and not field.startswith(("scenario.target.", "scenario.target[")):
        return error
    return type(error)("scenario.targets[0]" + field.removeprefix("scenario.target"), error.value, error.rule)

