"""The geometry of a recovery onto the moving carrier (pure, numpy): holdoff point, glide path,
the cone round it, and the contact conditions.

Frames: local NED [m], [m/s] (up is -z). The carrier's *course* is a horizontal unit vector (its
direction of travel). With D the dock point and c the course:

- final gate F = D + decision_height * up: directly above the dock point;
- holdoff point H = F - holdoff_distance * c + holdoff_distance * tan(glide angle) * up: behind and
  above the gate;
- glide path G(s) = H + s (F - H), s in [0, 1]: a straight descent at the glide angle onto the
  gate; from the gate the vehicle descends vertically onto D, and only once it is lined up;
- cone: on the glide path the vehicle may be at most ``cone_min_radius + |G(s) - F| tan(cone half
  angle)`` from G(s);
- contact: the vehicle within ``contact_radius`` of D horizontally and ``contact_height`` of it
  vertically, its velocity within the contact speeds of the carrier's (horizontal and vertical).
See docs/recovery.md for the phases that use them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

UP = np.array([0.0, 0.0, -1.0])
COURSE_MIN_SPEED_M_S = 0.3  # [m/s] below this the carrier's velocity gives no course: the last one stands


@dataclass(frozen=True)
class DockingGeometry:
    """holdoff_distance_m [m] behind the final gate; glide_angle_rad [rad] of the descent onto it;
    cone_half_angle_rad [rad] and cone_min_radius_m [m]: how far off the glide path the vehicle may
    be; decision_height_m [m]: the gate's height above the dock point, below which only a vehicle
    meeting the contact conditions horizontally goes on; contact_radius_m, contact_height_m [m];
    contact_max_horizontal_speed_m_s, contact_max_vertical_speed_m_s [m/s] relative to the carrier.
    No defaults: built from ``[recovery]`` (:func:`mission.model.docking_geometry`), whose schema
    holds the one default of each."""

    holdoff_distance_m: float
    glide_angle_rad: float
    cone_half_angle_rad: float
    cone_min_radius_m: float
    decision_height_m: float
    contact_radius_m: float
    contact_height_m: float
    contact_max_horizontal_speed_m_s: float
    contact_max_vertical_speed_m_s: float

    @property
    def holdoff_height_m(self) -> float:
        """Height [m] of the holdoff point above the dock point."""
        return self.decision_height_m + self.holdoff_distance_m * math.tan(self.glide_angle_rad)


def course(velocity_ned_m_s: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """The carrier's course: the horizontal unit vector of its velocity, or ``previous`` when it
    moves slower than :data:`COURSE_MIN_SPEED_M_S` [m/s]."""
    horizontal = np.array([velocity_ned_m_s[0], velocity_ned_m_s[1], 0.0], dtype=float)
    speed = float(np.linalg.norm(horizontal))
    return horizontal / speed if speed >= COURSE_MIN_SPEED_M_S else np.asarray(previous, dtype=float)


def gate_point(dock_ned_m: np.ndarray, g: DockingGeometry) -> np.ndarray:
    """F [m] NED: the final gate, ``decision_height_m`` straight above the dock point."""
    return np.asarray(dock_ned_m, dtype=float) + g.decision_height_m * UP


def holdoff_point(dock_ned_m: np.ndarray, course_unit: np.ndarray, g: DockingGeometry) -> np.ndarray:
    """H [m] NED: behind the gate along ``course_unit`` and above it on the glide path."""
    return (gate_point(dock_ned_m, g) - g.holdoff_distance_m * np.asarray(course_unit, dtype=float)
            + g.holdoff_distance_m * math.tan(g.glide_angle_rad) * UP)


def glide_point(dock_ned_m: np.ndarray, course_unit: np.ndarray, s: float, g: DockingGeometry) -> np.ndarray:
    """G(s) [m] NED: the glide path's point a fraction ``s`` of the way from H to the gate."""
    h = holdoff_point(dock_ned_m, course_unit, g)
    return h + min(max(s, 0.0), 1.0) * (gate_point(dock_ned_m, g) - h)


def path_length_m(g: DockingGeometry) -> float:
    """|F - H| [m]: the length of the glide path."""
    return g.holdoff_distance_m / math.cos(g.glide_angle_rad)


def cone_radius_m(glide_ned_m: np.ndarray, dock_ned_m: np.ndarray, g: DockingGeometry) -> float:
    """How far [m] the vehicle may be from the glide path's point ``glide_ned_m``."""
    to_gate = float(np.linalg.norm(np.asarray(glide_ned_m) - gate_point(dock_ned_m, g)))
    return g.cone_min_radius_m + to_gate * math.tan(g.cone_half_angle_rad)


@dataclass(frozen=True)
class Contact:
    """The vehicle against the dock point: horizontal_error_m, height_error_m (vehicle below the
    dock point: positive) [m]; horizontal_relative_speed_m_s, vertical_relative_speed_m_s [m/s]."""

    horizontal_error_m: float
    height_error_m: float
    horizontal_relative_speed_m_s: float
    vertical_relative_speed_m_s: float

    def within(self, g: DockingGeometry) -> bool:
        """All four contact conditions hold."""
        return (self.horizontal_error_m <= g.contact_radius_m and abs(self.height_error_m) <= g.contact_height_m
                and self.horizontal_relative_speed_m_s <= g.contact_max_horizontal_speed_m_s
                and self.vertical_relative_speed_m_s <= g.contact_max_vertical_speed_m_s)

    def horizontally_within(self, g: DockingGeometry) -> bool:
        """The horizontal conditions hold (position and speed): allowed below the decision height."""
        return (self.horizontal_error_m <= g.contact_radius_m
                and self.horizontal_relative_speed_m_s <= g.contact_max_horizontal_speed_m_s)


def contact(vehicle_ned_m: np.ndarray, vehicle_v_ned_m_s: np.ndarray, dock_ned_m: np.ndarray,
            carrier_v_ned_m_s: np.ndarray) -> Contact:
    """The vehicle's :class:`Contact` figures against the dock point and the carrier's velocity."""
    e = np.asarray(vehicle_ned_m, dtype=float) - dock_ned_m
    dv = np.asarray(vehicle_v_ned_m_s, dtype=float) - carrier_v_ned_m_s
    return Contact(float(np.hypot(e[0], e[1])), float(e[2]), float(np.hypot(dv[0], dv[1])), abs(float(dv[2])))


def heights_over_dock(n: float, g: DockingGeometry) -> float:
    """The final descent's progress (0 at the gate, 1 at the dock point) ``n`` contact heights
    over the dock point."""
    return 1.0 - n * g.contact_height_m / g.decision_height_m


def descent_step(descent: float, horizontal_error_m: float, g: DockingGeometry, speed_m_s: float,
                 final_speed_m_s: float | None, lineup_margin: float, dt_s: float) -> tuple[float, float]:
    """The final descent's progress one tick ``dt_s`` [s] on (``descent``: 0 at the gate, 1 at the
    dock point) and the rate [m/s] it goes down at, relative to the carrier: ``speed_m_s`` down
    to three contact heights over the dock point, below them ``final_speed_m_s`` (None: the same)
    and only while lined up within ``1 - lineup_margin`` of the contact radius
    (``horizontal_error_m`` [m], the vehicle from the dock point). Out of that it pauses (rate 0)
    where it is, no lower than two contact heights: the vehicle's vertical swing (~0.1 m round
    its reference) may take it into the contact band, but within the contact radius it docks
    there (beyond it the out-of-line rule holds it at three contact heights). Not its horizontal
    speed with a margin: the estimate's, PX4's velocity error in it, is over 0.14 m/s for seconds
    on a slow carrier, and a descent waiting for it went around on its budget; nor back up to
    three contact heights, or 2.5: the vehicle's horizontal error wanders 0.01-0.15 m within a
    second or two, and a descent sent back up at each excursion went around on its budget
    (docs/relnav.md, "The deck touches, the floor and P1")."""
    slow_from, pause = heights_over_dock(3.0, g), heights_over_dock(2.0, g)
    rate = final_speed_m_s if descent >= slow_from and final_speed_m_s is not None else speed_m_s
    nxt = min(1.0, descent + rate * dt_s / g.decision_height_m)
    if nxt > slow_from and horizontal_error_m > (1.0 - lineup_margin) * g.contact_radius_m:
        return min(descent, pause), 0.0
    return nxt, rate


def descent_progress(point_ned_m: np.ndarray, dock_ned_m: np.ndarray, g: DockingGeometry) -> float:
    """How far [0-1] down from the gate (0) to the dock point (1) ``point_ned_m`` [m] NED is, by its
    height over the dock point (clamped)."""
    height = float(np.asarray(dock_ned_m, dtype=float)[2] - np.asarray(point_ned_m, dtype=float)[2])
    return min(1.0, max(0.0, 1.0 - height / g.decision_height_m))


def wait_for_vehicle(descent: float, rate: float, x_ref: np.ndarray, vehicle_ned_m: np.ndarray, dock_ned_m: np.ndarray,
                     g: DockingGeometry, max_lag_m: float | None) -> tuple[float, float, np.ndarray]:
    """The final descent's progress and rate (:func:`descent_step`'s) and the reference's position
    ``x_ref`` [m] NED held, below three contact heights over the dock point, to no more than
    ``max_lag_m`` [m] below the vehicle's own height (``vehicle_ned_m`` [m] NED, its estimate; None:
    not held): the reference waits for a vehicle its vertical swing left above it. Held, the rate is
    0 and the progress the vehicle's plus that lag (no higher than three contact heights). PX4
    closes the position sent with the mission's lead (``mission.position_lead``), so a vehicle left
    0.1-0.15 m above its reference caught up at 0.5-0.7 m/s, into the contact band over its
    vertical speed (docs/relnav.md, "The last decimetre's speed"). The bound comes into force as the
    lag reaches it, so the reference moves on continuously."""
    slow_from = heights_over_dock(3.0, g)
    if max_lag_m is None or descent <= slow_from:
        return descent, rate, x_ref
    lowest = float(vehicle_ned_m[2]) + max_lag_m
    if x_ref[2] > lowest:
        x_ref = np.array([x_ref[0], x_ref[1], lowest])
    held = descent_progress(np.asarray(vehicle_ned_m, dtype=float) + np.array([0.0, 0.0, max_lag_m]), dock_ned_m, g)
    return (descent, rate, x_ref) if descent <= held else (max(held, slow_from), 0.0, x_ref)
