"""One control tick of the marsupial pair: law, separation latch, safety (pure, numpy).

The same functions serve the realtime controller (arrays of shape ``(n,)``) and the batch
simulator (``(B, n)``); neither knows how time advances or where states come from.

Anchor and separation latch (design decisions; docs/how-it-works.md, facts about the law 2 and 3):

- Before separation the *anchor* is the carrier's dock point; the passenger's law works in error
  coordinates ``e_pc = x_p - anchor``, and feeds forward the anchor's velocity.
- The separation event is the docked carrier reaching ``|e_tc| = b c - departure_margin``. At
  ``|e_tc| = b c`` exactly, ``e_pc = 0`` is an equilibrium (``P = 0``) that an exactly-docked
  passenger never leaves; the margin is the paper's ``T+``: the carrier coasts a hair past the
  unstable equilibrium so the separating branch has a (tiny) non-zero input. With the default
  1 mm the relative input starts at about 8 mm/s instead of jumping.
- At the event the anchor is latched: the passenger's law keeps using the carrier position and
  ``|e_tc|`` of that instant (paper Remark 1) whatever the carrier does next (it stops in the
  paper; it keeps its own plan under Remark 1; a real carrier also brakes over some distance).
  Latching only ``|e_tc|`` would let a carrier that drives away make ``P`` positive again and
  pull the passenger back, so the position is latched.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from mission.core.law import LawParams, carrier_command, dot, norm, passenger_command, uniform, where_rows
from mission.core.safety import DeckKeepOut, FilterResult, Neighbours, Obstacles, SafetyConfig, filter_velocity


DEPARTURE_THRESHOLD_M = 0.1  # |e_pc| [m] beyond which the passenger counts as having left the carrier


@dataclass(frozen=True)
class SeparationSpeed:
    """How slowly the carrier arrives at the separation: its approach's speed [m/s] is capped at
    ``sqrt(speed_m_s^2 + 2 decel_m_s2 max(|e_tc| - distance_m, 0))``, ``|e_tc|`` [m] its distance
    to the target as the law measures it (in its own frame; a planar carrier's counts the
    target's height). ``speed_m_s`` > 0 [m/s] from ``distance_m`` [m] in (``b c`` plus room for
    the frames' disagreement: the passenger separates at ``b c`` in its own), reached at
    ``decel_m_s2`` > 0 [m/s^2]. A carrier told to stop at the separation then stops from that
    speed: PX4's SIH rover, separating at up to 1.4 m/s, rolled 0.2-0.8 m on before it stood
    (docs/safety.md, "Arriving slowly, turning round away")."""

    speed_m_s: float
    decel_m_s2: float
    distance_m: float

    def cap_m_s(self, distance_m: np.ndarray) -> np.ndarray:
        """The speed cap [m/s] at the carrier-target distance ``distance_m`` [m] (any shape)."""
        room = np.maximum(np.asarray(distance_m, dtype=float) - self.distance_m, 0.0)
        return np.sqrt(self.speed_m_s * self.speed_m_s + 2.0 * self.decel_m_s2 * room)


@dataclass(frozen=True)
class TickModel:
    """Everything a tick needs besides the state.

    target [m] shape (n,) or (B, n); obstacles seen by the passenger (the carrier sees their
    planar projection when ``planar_carrier``); carrier_mode "stop" (paper eq. 4) or "remark1"
    (the carrier keeps its velocity of the separation instant); departure_margin_m [m].
    """

    law: LawParams
    target: np.ndarray
    obstacles: Obstacles
    passenger_safety: SafetyConfig
    carrier_safety: SafetyConfig
    planar_carrier: bool
    carrier_mode: Literal["stop", "remark1"] = "stop"
    departure_margin_m: float = 1e-3
    filter_carrier: bool = True
    carrier_obstacles: Obstacles | None = None  # default: obstacles (planar) + target keep-out
    other_keep_outs: Obstacles | None = None  # other targets' keep-outs the carrier steers round (target_keep_outs)
    separation_speed: SeparationSpeed | None = None  # the approach's speed falls towards the separation (None: off)

    def __post_init__(self) -> None:
        if self.carrier_obstacles is None:
            keepout = 0.5 * self.law.separation_distance_m if self.carrier_mode == "remark1" else 0.0
            obs = default_carrier_obstacles(self.obstacles, np.asarray(self.target), self.planar_carrier, keepout)
            others = self.other_keep_outs
            if others is not None and others.radii.shape[0] and obs.centers.ndim == 2:
                obs = Obstacles(np.concatenate([obs.centers, others.centers]), np.append(obs.radii, others.radii))
            object.__setattr__(self, "carrier_obstacles", obs)

    @property
    def event_distance_m(self) -> float:
        """Carrier-target distance [m] at which the separation event fires: ``b c - margin``."""
        return self.law.separation_distance_m - self.departure_margin_m


@dataclass(frozen=True)
class PassengerTick:
    """Passenger command of one tick. u [m/s] safe command; relative [m/s] the law's ``u_p -
    u_c`` before the filter; desired [m/s] the law's ``u_p`` (``u`` may be this very array when
    the filter changed nothing: read, never write into them); P [1/s]; leaving: separating
    branch; e_pc_norm_m [m] ``|e_pc|``."""

    u: np.ndarray
    desired: np.ndarray
    relative: np.ndarray
    P: np.ndarray
    leaving: np.ndarray
    safety: FilterResult
    e_pc_norm_m: np.ndarray


def passenger_tick(
    anchor: np.ndarray,
    anchor_velocity: np.ndarray,
    e_pc: np.ndarray,
    separated: np.ndarray | bool,
    model: TickModel,
    u_prev: np.ndarray | None = None,
    dt_s: float | None = None,
    e_tc_norm_m: np.ndarray | None = None,
    deck: DeckKeepOut | None = None,
    neighbours: Neighbours | None = None,
    since_separation_s: float | np.ndarray | None = None,
) -> PassengerTick:
    """Law + safety for the passenger at ``anchor + e_pc`` [m].

    anchor_velocity [m/s] is fed forward while docked (the carrier command, or a measured dock
    velocity); after separation nothing is fed forward (the anchor is latched).
    ``e_tc_norm_m`` [m]: ``|target - anchor|`` when the caller has it already (else computed).
    ``deck``: the keep-out round the carrier's deck the filter keeps the passenger out of.
    ``neighbours``: the other passengers the filter keeps it apart from (their last shared states,
    :func:`mission.core.safety.neighbour_rows`; its own velocity there is ``u_prev``);
    ``since_separation_s`` [s]: the time since the passenger separated, over which their rows
    phase in (``passenger_safety.separation_phase_in_s``; None: fully in).
    """
    sep = np.asarray(separated, dtype=bool)
    e_tc = model.target - anchor
    u_ff = where_rows(sep, 0.0, anchor_velocity)
    cmd = passenger_command(e_pc, e_tc, u_ff, model.law, e_tc_norm_m)
    desired = cmd.u_p
    a_max = model.passenger_safety.max_accel_m_s2
    shaped = False if a_max is None else uniform(sep)  # True: all separated, None: some
    if shaped is not False:  # (the scale below is exactly 1 where docked: skipped if all are)
        # Arrival shaping: never faster than the speed from which the acceleration limit can
        # still stop at the target; keeps the direction. With ticks of dt the speed that stops
        # exactly at the target, braking by a_max dt per tick and moving by the new speed each
        # tick, is sqrt((a_max dt / 2)^2 + 2 a_max d) - a_max dt / 2 (d the distance left).
        # Why, and what the continuous sqrt(2 a_max d) did: docs/how-it-works.md, arrival shaping.
        half_step = 0.0 if dt_s is None else 0.5 * a_max * dt_s
        stop_speed = np.sqrt(half_step * half_step + 2.0 * a_max * norm(e_pc - e_tc)) - half_step
        speed = norm(desired)
        scale = np.minimum(1.0, stop_speed / np.maximum(speed, 1e-300))
        if shaped is None:
            scale = np.where(sep, scale, 1.0)
        desired = desired * scale[..., None]
    safe = filter_velocity(anchor + e_pc, desired, model.obstacles, model.passenger_safety, u_prev, dt_s, copy=False,
                           deck=deck, neighbours=neighbours, since_separation_s=since_separation_s)
    return PassengerTick(u=safe.u, desired=desired, relative=cmd.relative, P=cmd.P, leaving=cmd.leaving, safety=safe,
                         e_pc_norm_m=cmd.e_pc_norm_m)


def carrier_tick(
    x_c: np.ndarray,
    separated: np.ndarray | bool,
    model: TickModel,
    own_plan_velocity: np.ndarray | None = None,
    u_prev: np.ndarray | None = None,
    dt_s: float | None = None,
    course_velocity: np.ndarray | None = None,
) -> FilterResult:
    """Carrier command [m/s] at ``x_c`` [m]: the paper's approach while docked; after
    separation zero ("stop") or ``own_plan_velocity`` ("remark1"); ``course_velocity`` [m/s]
    instead when given (the recovery course: :mod:`mission.carrier.course`); filtered for
    obstacles, speed and acceleration alike."""
    sep = np.asarray(separated, dtype=bool)
    if course_velocity is not None:
        u = np.array(np.broadcast_to(np.asarray(course_velocity, dtype=float), x_c.shape))  # a new array
        if model.planar_carrier and x_c.shape[-1] == 3:
            u[..., 2:] = 0.0
    else:
        e_tc = model.target - x_c
        u = carrier_command(e_tc, ~sep, model.law, planar=model.planar_carrier)  # a new array
        if model.separation_speed is not None:  # it arrives at the separation slowly (separated rows: u = 0)
            speed = norm(u)
            cap = model.separation_speed.cap_m_s(norm(e_tc))
            u = u * (np.minimum(speed, cap) / np.maximum(speed, 1e-12))[..., None]
    if course_velocity is None and model.carrier_mode == "remark1" and own_plan_velocity is not None and uniform(sep) is not False:
        u = np.where(sep[..., None], own_plan_velocity, u)  # a new array too
    obstacles = model.carrier_obstacles if model.filter_carrier else Obstacles.none(2 if model.planar_carrier else x_c.shape[-1])
    others = model.other_keep_outs
    # (the other targets' keep-outs are the last rows of shared obstacle centres (m, d): TickModel appends them only there)
    if model.filter_carrier and others is not None and len(others) and obstacles is not None and obstacles.centers.ndim == 2:
        k, lim = obstacles.centers.shape[-1], model.carrier_safety
        brake = lim.max_accel_m_s2 * dt_s if lim.max_accel_m_s2 is not None and dt_s is not None else math.inf
        obstacles = keep_outs_at(obstacles, len(others), x_c[..., :k], lim.margin_m,
                                 None if u_prev is None else u_prev[..., :k], lim.cbf_gain, brake)
    if model.filter_carrier and others is not None and len(others) and obstacles is not None and obstacles.centers.ndim == 2:
        k = obstacles.centers.shape[-1]
        u[..., :k] = round_keep_outs(x_c[..., :k], u[..., :k], obstacles.centers[-len(others):],
                                     obstacles.radii[..., -len(others):] + model.carrier_safety.margin_m)
    if model.planar_carrier and x_c.shape[-1] == 3:
        in_plane = u[..., :2]
        planar = filter_velocity(x_c[..., :2], in_plane, obstacles, model.carrier_safety,
                                 None if u_prev is None else u_prev[..., :2], dt_s, copy=False)
        if planar.u is not in_plane:  # u is ours: reuse it as the 3D command, in the plane
            u[..., :2] = planar.u
        u[..., 2:] = 0.0
        return FilterResult(u, planar.changed, planar.correction_m_s, planar.feasible, planar.cbf_active)
    return filter_velocity(x_c, u, obstacles, model.carrier_safety, u_prev, dt_s, copy=False)


ROUND_BAND_M = 2.0  # [m] the carrier begins to veer round another target's keep-out this far outside its row's radius
ROUND_SHARE = 0.5  # [-] ... by up to this fraction of its speed (head-on, at the row's radius)
ROUND_SIDE = 0.2  # [-] its side: the command's own, full once it passes this fraction of its speed off the centre ...
ROUND_RIGHT = 0.5  # [-] ... with this bias to the right (straight at the centre: half the veer, to the right)


def round_keep_outs(x_m: np.ndarray, u: np.ndarray, centers_m: np.ndarray, radii_m: np.ndarray,
                    band_m: float = ROUND_BAND_M, share: float = ROUND_SHARE) -> np.ndarray:
    """The carrier's command ``u`` [m/s] (..., k) at ``x_m`` [m] with a veer round the other
    targets' keep-outs it heads into (``centers_m`` (m, k) [m], ``radii_m`` (m,) or (..., m) [m]:
    their rows' radii, the margin included): for each, ``share |u| w s`` to the right of the
    direction to its centre (NED x north, y east: right of north is east; in the horizontal plane),
    ``w`` the cosine between ``u`` and that direction (0 when it heads away or past) times the
    nearness (0 at ``band_m`` outside the radius, 1 at it), ``s`` in [-1, 1] the side ``u``
    already passes on (its part to the right of the centre over :data:`ROUND_SIDE` ``|u|``) plus
    :data:`ROUND_RIGHT`: the short way round, and to the right when it heads straight at the
    centre. Always to the right, a carrier between two keep-outs was pushed by one into the other
    and stood (team Monte-Carlo #30). Continuous in the state and the command (no jump). The barrier row alone takes away the inward part of a command that heads
    straight at a keep-out's centre and leaves nothing: a carrier whose next target lay behind
    another's keep-out stopped at its edge for good (team Monte-Carlo #52: 850 s, until the
    mission's time ran out), an undesired equilibrium of the barrier's quadratic program."""
    rel = centers_m - x_m[..., None, :]
    dist = norm(rel)
    to = rel / np.maximum(dist, 1e-9)[..., None]
    speed = norm(u)
    cos = np.maximum(dot(to, u[..., None, :]) / np.maximum(speed, 1e-9)[..., None], 0.0)
    near = np.clip(1.0 - (dist - radii_m) / band_m, 0.0, 1.0)
    w = cos * near
    if not np.any(w > 0.0):
        return u
    right = np.zeros(to.shape)
    right[..., 0], right[..., 1] = -to[..., 1], to[..., 0]
    side = np.clip(dot(right, u[..., None, :]) / (ROUND_SIDE * np.maximum(speed, 1e-9))[..., None] + ROUND_RIGHT, -1.0, 1.0)
    return u + share * speed[..., None] * np.sum((w * side)[..., None] * right, axis=-2)


def default_carrier_obstacles(obstacles: Obstacles, target: np.ndarray, planar: bool, keepout_m: float) -> Obstacles:
    """What the carrier avoids: the obstacles (their planar projection for a planar carrier)
    plus, when ``keepout_m > 0``, a keep-out disc of that radius [m] around the target, so that a
    carrier that keeps its own plan after separation (Remark 1) still never reaches the target
    (P3). A batch of targets (B, n) gives per-scenario obstacle centres (B, m + 1, n)."""
    obs = obstacles.planar() if planar else obstacles
    if keepout_m <= 0:
        return obs
    centre = target[..., :2] if planar else target
    centers = np.broadcast_to(obs.centers, centre.shape[:-1] + obs.centers.shape[-2:])
    return Obstacles(np.concatenate([centers, centre[..., None, :]], axis=-2), np.append(obs.radii, keepout_m))


def keep_outs_at(obstacles: Obstacles, count: int, x_m: np.ndarray, margin_m: float, u_prev: np.ndarray | None = None,
                 gain: float = 1.0, brake_m_s: float = math.inf) -> Obstacles:
    """``obstacles`` with their last ``count`` (the other targets' keep-outs, :func:`target_keep_outs`)
    shrunk where the carrier at ``x_m`` [m] (one state (d,) or a batch (B, d), in the obstacles'
    dimension d) is inside one (radius + ``margin_m`` [m] beyond its distance): radius ``min(r, |x -
    o| - margin)``, so the barrier holds it where it is (no deeper) and never pushes it out. A
    carrier begins a leg wherever the last leg left it, often at the previous target's guard
    circle, inside that target's keep-out: pushed out at the barrier's rate, ``cbf_gain`` x its
    depth, its command jumped past its acceleration limit (1.2 m/s in a tick) under the riding
    passenger (docs/recovery.md, "Monte-Carlo of the cycle").

    With the last command ``u_prev`` [m/s] (same shape as ``x_m``), the barrier's gain ``gain``
    [1/s] and ``brake_m_s`` [m/s] the most its speed may fall in one step (acceleration limit x
    step), a keep-out the carrier drives into is shrunk further, so that its row (``2 (x - o) . u
    >= -gain h``) asks the inward speed to fall by at most ``brake_m_s`` this step: a team's
    carrier handed over at one target's separation circle, driving at it at 1.6 m/s, has that
    target's keep-out as a new row, which stopped it dead in one step under the next riding
    passenger (docs/team.md). The carrier then brakes at its limit; each target's P3 guard still
    caps it (:mod:`mission.carrier.guard`). For a batch the radii come back per state, (B, m).
    Unchanged (the same object) where every state is outside all."""
    radii = obstacles.radii[..., -count:]
    diff = x_m[..., None, :] - obstacles.centers[..., -count:, :]
    dist = norm(diff)
    reach = dist
    if u_prev is not None and math.isfinite(brake_m_s):
        inward = np.maximum(-dot(diff, np.asarray(u_prev, dtype=float)[..., None, :]) / np.maximum(dist, 1e-9), 0.0)
        allowed = np.maximum(inward - brake_m_s, 0.0)
        reach = np.sqrt(np.maximum(dist ** 2 - 2.0 * dist * allowed / gain, 0.0))
    fitted = np.minimum(radii, np.maximum(reach - margin_m, 0.0))
    if np.all(fitted >= radii):
        return obstacles
    kept = obstacles.radii[..., :-count]
    kept = np.broadcast_to(kept, fitted.shape[:-1] + kept.shape[-1:])
    return Obstacles(obstacles.centers, np.concatenate([kept, fitted], axis=-1))


def target_keep_outs(targets: list[np.ndarray], radius_m: float, planar: bool, plane_down_m: float = 0.0) -> Obstacles:
    """Keep-outs [m] round ``targets`` (each (n,), NED) that a carrier steers round with its
    barrier rows (a multi-target mission: the targets of the other legs): spheres of
    ``radius_m``, for a planar carrier their discs in its plane (down ``plane_down_m``),
    ``sqrt(radius_m^2 - height^2)`` (none for a target higher above the plane than that)."""
    n = 2 if planar else (targets[0].shape[-1] if targets else 2)
    keep = []
    for t in targets:
        t = np.asarray(t, dtype=float)
        if planar and t.shape[-1] == 3:
            height2 = (float(t[2]) - plane_down_m) ** 2
            if height2 < radius_m * radius_m:
                keep.append((t[:2], float(np.sqrt(radius_m * radius_m - height2))))
        else:
            keep.append((t[:n], radius_m))
    if not keep:
        return Obstacles.none(n)
    return Obstacles(np.array([c for c, _ in keep]), np.array([r for _, r in keep]))


def separation_due(anchor: np.ndarray, separated: np.ndarray | bool, model: TickModel,
                   distance_m: np.ndarray | None = None) -> np.ndarray:
    """True where a docked pair has reached the event distance (the latch fires).

    ``distance_m`` [m]: ``|target - anchor|`` when the caller has it already (else computed)."""
    if distance_m is None:
        distance_m = norm(model.target - anchor)
    return ~np.asarray(separated, dtype=bool) & (distance_m <= model.event_distance_m)


def latch_point(previous: np.ndarray, anchor: np.ndarray, target: np.ndarray, model: TickModel) -> tuple[np.ndarray, np.ndarray]:
    """Where the latch fired inside the step ``previous -> anchor`` [m] (a straight segment: the
    anchor moved at constant velocity over the tick): (theta in [0, 1], the anchor at the event).
    Shared by the realtime phases and the batch simulator."""
    step = anchor - previous
    theta = crossing_fraction(previous, step, target, model.event_distance_m)
    return theta, previous + theta[..., None] * step


def crossing_fraction(start: np.ndarray, step: np.ndarray, target: np.ndarray, radius: float) -> np.ndarray:
    """Fraction theta in [0, 1] of a straight step ``start -> start + step`` [m] at which the
    distance to ``target`` first equals ``radius`` [m] (exact: a quadratic in theta).
    Returns 1 where the step does not reach the sphere."""
    w = start - target
    a = np.einsum("...i,...i->...", step, step)
    b = 2.0 * np.einsum("...i,...i->...", w, step)
    c = np.einsum("...i,...i->...", w, w) - radius**2
    disc = np.maximum(b * b - 4 * a * c, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        theta = (-b - np.sqrt(disc)) / (2 * a)
    theta = np.where((a > 0) & np.isfinite(theta), theta, 1.0)
    return np.clip(theta, 0.0, 1.0)
