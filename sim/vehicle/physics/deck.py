"""The carrier's moving deck under the mock vehicle: touchdown, riding on it, crashes. Times are
the vehicle's simulated seconds [s], positions [m] and velocities [m/s] local NED.

The deck is a horizontal disc of radius ``radius_m`` centred ``height_m`` above the carrier's
reported position, moving with the carrier's velocity (its last state moved on by that velocity
since it arrived). Each physics step:

- **touchdown**: the vehicle crossed the deck's plane from above, within ``radius_m`` of its
  centre. Its speed relative to the deck decides: at most ``max_vertical_m_s`` down and
  ``max_horizontal_m_s`` across, it has landed; faster, it has crashed (the reason says which
  speed, by how much). Crossing the plane between ``radius_m`` and ``radius_m + edge_m`` (the
  vehicle's own half span) is a crash off the deck's edge; farther out it misses the deck and
  flies on (towards the ground).
- **landed**: the vehicle rides with the deck (its position pinned where it touched down, its
  velocity the deck's) until it rises from the plane (a take-off: above it and climbing relative
  to it). PX4's land detector sees
  ground contact only while the vehicle moves slower than ``LNDMC_XY_VEL_MAX`` (1.5 m/s)
  horizontally: on a slower deck it reports ON_GROUND and disarms after COM_DISARM_LAND; on a
  faster one it believes it is flying (IN_AIR, no auto-disarm), as PX4 would.
- **crashed**: the airframe is wreckage on the deck: carried with it, never flying again.
- A vehicle standing within the disc on its plane when the deck is first known starts on it.
- *Not modelled: the carrier's sides (a vehicle below the plane within the disc passes through),
  a tilted deck, the vehicle's attitude at contact.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from sim.vehicle.physics.multicopter import KinState
from mission.core.records import replace

START_ON_DECK_M = 0.05  # standing this close to the plane at the first deck state: on the deck [m]
LAND_DETECT_XY_M_S = 1.5  # PX4's LNDMC_XY_VEL_MAX: faster than this horizontally, no ground contact [m/s]


@dataclass(frozen=True)
class DeckSpec:
    """The deck: height above the carrier's position [m], radius [m], the vehicle's half span
    [m] (the band off the edge that is a crash), and the touchdown limits relative to the deck
    [m/s]: vertical (descending) and horizontal; ``offset_ne_m`` [m] north, east: where its
    centre sits from the carrier's position (a team's slot, ``team.slots[].offset_ned_m``)."""

    height_m: float = 0.0
    radius_m: float = 0.5
    edge_m: float = 0.25
    max_vertical_m_s: float = 1.0
    max_horizontal_m_s: float = 0.5
    offset_ne_m: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ("radius_m", "max_vertical_m_s", "max_horizontal_m_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"deck {name} must be > 0, got {getattr(self, name)!r}")
        if not (self.edge_m >= 0 and math.isfinite(self.height_m)):
            raise ValueError(f"deck edge_m must be >= 0 and height_m finite, got {self.edge_m!r}, {self.height_m!r}")


@dataclass(frozen=True)
class DeckMotion:
    """The carrier as last heard: position [m] and velocity [m/s] NED at vehicle time ``t_s`` [s]."""

    position_ned_m: tuple[float, float, float]
    velocity_ned_m_s: tuple[float, float, float]
    t_s: float

    def centre(self, t_s: float, height_m: float) -> tuple[float, float, float]:
        """The deck's centre at ``t_s`` [s]: moved on by the velocity, ``height_m`` above."""
        dt = t_s - self.t_s
        p, v = self.position_ned_m, self.velocity_ned_m_s
        return p[0] + v[0] * dt, p[1] + v[1] * dt, p[2] + v[2] * dt - height_m


def _shifted(centre: tuple[float, float, float], offset_ne_m: tuple[float, float]) -> tuple[float, float, float]:
    return centre[0] + offset_ne_m[0], centre[1] + offset_ne_m[1], centre[2]


@dataclass(frozen=True)
class Touchdown:
    """One contact with the deck: when [s], where relative to its centre (horizontal [m]), the
    speeds relative to the deck [m/s], and what came of it (``crash`` None: landed)."""

    t_s: float
    horizontal_error_m: float
    vertical_speed_m_s: float
    horizontal_speed_m_s: float
    crash: str | None


class Deck:
    """The deck under one vehicle: :meth:`refresh` takes the carrier's newest motion from
    ``source`` (None until one is known), :meth:`step` applies the deck to each physics step."""

    def __init__(self, spec: DeckSpec, land_detect_xy_m_s: Callable[[], float] = lambda: LAND_DETECT_XY_M_S) -> None:
        self.spec = spec
        self.land_detect_xy_m_s = land_detect_xy_m_s
        self.source: Callable[[], DeckMotion | None] | None = None
        self.motion: DeckMotion | None = None
        self.offset_ne: tuple[float, float] | None = None  # on the deck: where, from its centre [m]
        self.crash: str | None = None
        self.touchdowns: list[Touchdown] = []

    def refresh(self) -> bool:
        """Take the carrier's newest motion from ``source``; True if the vehicle has crashed already."""
        motion = self.source() if self.source is not None else None
        if motion is not None:
            self.motion = motion
        return self.crash is not None

    @property
    def on_deck(self) -> bool:
        return self.offset_ne is not None

    def top(self, t_s: float) -> tuple[float, float, float] | None:
        """The centre of the deck's top at ``t_s`` [s] (NED [m]); None while the carrier is not known."""
        motion = self.motion
        return None if motion is None else _shifted(motion.centre(t_s, self.spec.height_m), self.spec.offset_ne_m)

    def step(self, t_s: float, dt_s: float, before: KinState, after: KinState) -> KinState:
        """The vehicle's state after the step from ``before`` to ``after`` (``dt_s`` [s], ending at
        ``t_s`` [s]) once the deck had its say (see the module docstring)."""
        motion, s = self.motion, self.spec
        if motion is None:
            return after
        centre = _shifted(motion.centre(t_s, s.height_m), s.offset_ne_m)
        if self.offset_ne is not None:
            if self.crash is None and after.d_m < centre[2] and after.vd_m_s < motion.velocity_ned_m_s[2]:
                self.offset_ne = None  # took off: rising from the deck
                return after
            return self._ride(after, centre, motion.velocity_ned_m_s)
        was = _shifted(motion.centre(t_s - dt_s, s.height_m), s.offset_ne_m)  # the deck when the step began
        off_n, off_e = before.n_m - was[0], before.e_m - was[1]
        if not self.touchdowns and before.on_ground and abs(before.d_m - was[2]) <= START_ON_DECK_M \
                and math.hypot(off_n, off_e) <= s.radius_m:  # standing on it when it is first known
            self.touchdowns.append(Touchdown(t_s, math.hypot(off_n, off_e), 0.0, 0.0, None))
            self.offset_ne = (off_n, off_e)
            return self._ride(after, centre, motion.velocity_ned_m_s)
        if not before.d_m - was[2] < 0.0 <= after.d_m - centre[2]:  # not crossing the plane downwards
            return after
        return self._touch(t_s, before, after, centre, motion.velocity_ned_m_s)

    def _touch(self, t_s: float, before: KinState, after: KinState, centre: tuple[float, float, float],
               v_deck: tuple[float, float, float]) -> KinState:
        s = self.spec
        off_n, off_e = after.n_m - centre[0], after.e_m - centre[1]
        r = math.hypot(off_n, off_e)
        if r > s.radius_m + s.edge_m:
            return after  # beside the deck
        down = before.vd_m_s - v_deck[2]
        across = math.hypot(before.vn_m_s - v_deck[0], before.ve_m_s - v_deck[1])
        if r > s.radius_m:
            crash: str | None = f"off the deck's edge: {r:.2f} m from its centre (radius {s.radius_m:g} m)"
        elif down > s.max_vertical_m_s:
            crash = f"hit the deck at {down:.2f} m/s vertically (limit {s.max_vertical_m_s:g} m/s)"
        elif across > s.max_horizontal_m_s:
            crash = f"hit the deck at {across:.2f} m/s across it (limit {s.max_horizontal_m_s:g} m/s)"
        else:
            crash = None
        self.touchdowns.append(Touchdown(t_s, r, down, across, crash))
        self.crash = crash
        self.offset_ne = (off_n, off_e)
        return self._ride(after, centre, v_deck)

    def _ride(self, kin: KinState, centre: tuple[float, float, float], v_deck: tuple[float, float, float]) -> KinState:
        """``kin`` standing on the deck where it touched down, moving with it."""
        assert self.offset_ne is not None
        return replace(kin, n_m=centre[0] + self.offset_ne[0], e_m=centre[1] + self.offset_ne[1], d_m=centre[2],
                       vn_m_s=v_deck[0], ve_m_s=v_deck[1], vd_m_s=v_deck[2], an_m_s2=0.0, ae_m_s2=0.0, ad_m_s2=0.0,
                       ground_d_m=centre[2], on_ground=True)

    def as_px4_sees(self, kin: KinState) -> KinState:
        """``kin`` as PX4's land detector reads it: on a deck moving at LNDMC_XY_VEL_MAX or faster
        there is no ground contact (a wreck aside, which the commander never sees fly)."""
        if self.offset_ne is None or self.crash is not None or math.hypot(kin.vn_m_s, kin.ve_m_s) < self.land_detect_xy_m_s():
            return kin
        return replace(kin, on_ground=False)
