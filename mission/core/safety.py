"""Safety filter (pure, numpy): CBF-QP obstacle and altitude constraints, accel and speed limits.

A desired velocity ``u_des`` [m/s] at position ``x`` [m] (arrays ``(..., n)``) is changed as
little as possible (least squares) so that every barrier stays non-negative:

- obstacle i (circle in 2D, sphere in 3D): ``h_i = |x - o_i|^2 - (r_i + margin)^2``,
  constraint ``dh_i/dt = 2 (x - o_i) . u >= -gain * h_i``;
- optional bounds on the third coordinate (``z_min_m <= z <= z_max_m``; in PX4's NED frame
  an altitude floor of 2 m is ``z_max_m = -2``): ``+-u_z >= -gain * (distance to the bound)``.

- optional keep-out round a moving deck (:class:`DeckKeepOut`, 3D NED): below ``clear_height_m``
  above the deck and within the funnel's rim, ``h = radius + slope * max(height, 0) - r`` (``r`` the
  horizontal distance from the deck's centre, ``height`` above its plane), with the deck's velocity
  ``v_d``: ``dh/dt = grad h . (u - v_d) >= -gain * h``. The passenger may move out sideways
  relative to the deck only as it climbs: it clears the deck first.
- optional other passengers (:class:`Neighbours`, the pairwise separation barrier): see
  :func:`neighbour_rows` (docs/team.md, "Keeping passengers apart"), its rows phasing in from the
  passenger's separation.

The QP is solved in closed form where that is exact (no constraint violated, or a projection on
one violated constraint that satisfies all others: it meets the KKT conditions, so it is the
optimum) and by DAQP otherwise. If the QP is infeasible the fallback is zero velocity (hold
position) and ``feasible`` is false.

Order: the change of command is first limited to ``max_accel_m_s2 * dt_s`` (along the change),
then the barriers act, then the speed is limited to ``max_speed_m_s`` by scaling (the direction is
kept, and scaling towards zero never breaks a satisfied barrier constraint). So the barriers have
the last word: when an obstacle demands a harder stop than the acceleration limit allows, safety
wins over comfort (``cbf_active`` says so). With neighbours, a blocked meeting first veers the
command right (:func:`veer_right`, before the acceleration limit), and the speed limit never
scales below what a neighbour's row needs (:func:`limit_speed_keeping`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import daqp
import numpy as np

from mission.core.law import dot, norm

_TOL = 1e-9


@dataclass(frozen=True)
class Obstacles:
    """Circular (2D) or spherical (3D) obstacles: centers [m] shape (m, n) (or (B, m, n) for a
    batch with per-scenario obstacles), radii [m] shape (m,) (or (B, m) for per-scenario radii:
    a batch of carriers' keep-outs each shrunk to where its carrier is, :func:`mission.core.tick.keep_outs_at`).

    Treat the arrays as immutable: values derived from them (the planar view, squared keep-out
    radii) are computed once per instance and cached, since the filter needs them every tick.
    """

    centers: np.ndarray
    radii: np.ndarray
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @classmethod
    def none(cls, n: int) -> "Obstacles":
        return cls(np.zeros((0, n)), np.zeros(0))

    @classmethod
    def of(cls, items: list[tuple[list[float], float]], n: int) -> "Obstacles":
        if not items:
            return cls.none(n)
        centers = np.array([c for c, _ in items], dtype=float).reshape(-1, n)
        return cls(centers, np.array([r for _, r in items], dtype=float))

    def __len__(self) -> int:
        return int(self.radii.shape[-1])

    def planar(self) -> "Obstacles":
        """The same obstacles seen by a planar robot: their first two coordinates (circles)."""
        view = self._cache.get("planar")
        if view is None:
            view = self._cache["planar"] = Obstacles(self.centers[..., :2], self.radii)
        return view

    def keepout_sq(self, margin_m: float) -> np.ndarray:
        """Squared keep-out radii ``(r_i + margin)^2`` [m^2], shape (m,) or (B, m) as the radii (cached per margin)."""
        key = ("keepout_sq", margin_m)
        r2 = self._cache.get(key)
        if r2 is None:
            r2 = self._cache[key] = (self.radii + margin_m) ** 2
        return r2

    def clearance(self, x: np.ndarray) -> np.ndarray:
        """Distance [m] from ``x`` (..., n) to each obstacle's surface: shape (..., m)."""
        diff = x[..., None, :] - self.centers
        return norm(diff) - self.radii


CHANGED_M_S = 1e-12  # [m/s] a correction over this is the filter changing the command (per axis too)


@dataclass(frozen=True)
class SafetyConfig:
    """Parameters of the filter. None disables a limit.

    cbf_gain [1/s] class-K gain; margin_m [m] added to every radius; max_speed_m_s [m/s];
    max_accel_m_s2 [m/s^2]; z_min_m / z_max_m [m] bounds on the third coordinate;
    separation_m [m] the least distance kept from other passengers (None: no pairwise barrier);
    neighbour_max_age_s [s] an other passenger's sample older than this is left out;
    separation_phase_in_s [s] the pairwise rows phase in over this time from the passenger's
    separation (:func:`neighbour_rows`; 0: in at once); separation_vertical_ratio [-] the pairwise
    barrier's vertical half-axis over its level one (3D: an ellipsoid, a passenger straight above
    or below kept ``separation_m`` times this; 1: a sphere). (``_cache`` holds the constant
    constraint rows of the bounds, built on first use.)
    """

    cbf_gain: float = 1.0
    margin_m: float = 0.5
    max_speed_m_s: float | None = None
    max_accel_m_s2: float | None = None
    z_min_m: float | None = None
    z_max_m: float | None = None
    separation_m: float | None = None
    neighbour_max_age_s: float = 0.5
    separation_phase_in_s: float = 0.0
    separation_vertical_ratio: float = 1.0
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)


@dataclass(frozen=True)
class Neighbours:
    """The other passengers, as their last shared states: positions_m [m] (k, n) (or (B, k, n)
    for a batch), velocities_m_s [m/s] the same shape, frame as the filtered state's (NED);
    age_s [s] each sample's age at this tick, (k,) or (B, k) (None: all fresh). A sample counts
    as flown on at its velocity over its age; one older than ``neighbour_max_age_s`` is left
    out, as if absent. ``phases``: each neighbour's mission phase name as it shared it (None:
    not shared), for the recovery queue (:mod:`mission.phases.queue`), as are ``recovery_s`` [s]
    how long each one's recovery had run at its sample (None: not recovering, or not shared),
    ``battery_pct`` [%] its battery (None: not known), ``ids`` its MAVLink system id (the
    queue's tie-break) and ``targets_ned_m`` [m] (k, 3) the target of the leg it flies or rides
    for (None: not shared); the barrier reads none of them. ``distance_m`` [m] (k,): the distance
    kept from each one, where it differs per neighbour (None: ``separation_m`` of the filter's
    configuration for all; the recovery keeps the deck's seated passengers only at the span,
    :func:`mission.phases.queue.apart`); ``on_deck`` (k,) bool: kept on a sphere whatever
    ``separation_vertical_ratio`` (the deck's obstacles, whose span is level; None: none)."""

    positions_m: np.ndarray
    velocities_m_s: np.ndarray
    age_s: np.ndarray | None = None
    phases: tuple[str, ...] | None = None
    recovery_s: tuple[float | None, ...] | None = None
    battery_pct: tuple[float | None, ...] | None = None
    ids: tuple[int, ...] | None = None
    targets_ned_m: np.ndarray | None = None
    distance_m: np.ndarray | None = None
    on_deck: np.ndarray | None = None

    @classmethod
    def of(cls, items: list[tuple[list[float], list[float], float]], n: int) -> "Neighbours":
        """From ``[(position [m], velocity [m/s], age [s]), ...]``."""
        pos = np.array([p for p, _, _ in items], dtype=float).reshape(-1, n)
        vel = np.array([v for _, v, _ in items], dtype=float).reshape(-1, n)
        return cls(pos, vel, np.array([a for _, _, a in items], dtype=float))

    def __len__(self) -> int:
        return int(self.positions_m.shape[-2])

    def now(self, max_age_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """(positions moved on by their age [m], velocities [m/s], which are fresh: a bool mask
        of shape (k,) or (B, k), or None when all are)."""
        if self.age_s is None:
            return self.positions_m, self.velocities_m_s, None
        age = np.asarray(self.age_s, dtype=float)
        fresh = age <= max_age_s
        moved = self.positions_m + self.velocities_m_s * np.where(fresh, age, 0.0)[..., None]
        return moved, self.velocities_m_s, None if fresh.all() else fresh


TIE_BREAK = 0.5  # [-] a blocked passenger veers by this fraction of its speed (veer_right)
VEER_RAD = float(np.radians(120.0))  # the veer's direction: this far right of the direction to the neighbour


def phase_in_weight(since_s: float | np.ndarray, phase_in_s: float) -> np.ndarray:
    """The share [-] of the pairwise rows in force ``since_s`` [s] after the separation: 0 at it, 1
    from ``phase_in_s`` [s] on, a smoothstep between (``3 x^2 - 2 x^3``, ``x = since / phase_in``):
    its rate is zero at both ends, so the rows neither start nor finish with a kink, and early on
    (the latch, SEPARATED -> NAVIGATING a few ticks later) they ask almost nothing."""
    x = np.clip(np.asarray(since_s, dtype=float) / phase_in_s, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def neighbour_rows(x: np.ndarray, own_velocity: np.ndarray, neighbours: Neighbours,
                   cfg: SafetyConfig, since_separation_s: float | np.ndarray | None = None,
                   ) -> tuple[np.ndarray, np.ndarray] | None:
    """The pairwise separation barrier's rows ``A u >= b`` at ``x`` (..., n): A (..., k, n), b
    (..., k); None when there is none (no ``separation_m``, no neighbour, or all stale).

    ``h_j = |x - p_j|_W^2 - D^2`` with ``p_j`` the neighbour's position, ``D = separation_m`` (or
    the neighbour's own ``Neighbours.distance_m``) and ``|d|_W^2 = d . W d``, ``W = diag(1, 1,
    1 / separation_vertical_ratio^2)`` in 3D (an ellipsoid: a neighbour straight above or below is
    kept ``D`` times the ratio away; the identity, a sphere, at ratio 1, in 2D and for a neighbour
    ``Neighbours.on_deck``: a seated passenger is an obstacle of the deck's approach, its span
    level). Both
    passengers move, so ``dh_j/dt = 2 W (x - p_j) . (u - v_j)`` and the pair needs
    ``dh_j/dt >= -gain h_j``. Responsibility is shared reciprocally (each takes half the change of
    the pair's relative velocity, as ORCA does): with ``v_i`` this passenger's own velocity (its
    previous command), its row is ``2 W (x - p_j) . u >= W (x - p_j) . (v_i + v_j) - gain h_j / 2``.
    When the neighbour runs the same row on the same states the two rows add up to the pair's
    condition exactly; when it does not react (it holds, or flies without the filter) ``v_i``
    follows this passenger's own command and the row tends to the whole condition at half the
    remaining gap per tick. A pair already closer than ``D`` (slots on one deck) is held at its
    distance (``D`` shrunk to it), never pushed apart: a push would be a jump of the command.

    The phase-in: ``since_separation_s`` [s], the time since this passenger separated (scalar or
    (...)), within ``cfg.separation_phase_in_s`` of it, relaxes each row by ``(1 - w)`` of what
    the own velocity lacks of it, ``w`` :func:`phase_in_weight` (0 at the latch, 1 at the end):
    ``b' = b - (1 - w) max(0, b - A v_i)``. While riding a passenger flies its dock point, so its
    rows were absent; at the latch its previous command already breaks a row by half the pair's
    relative velocity along their line as the samples show it (two passengers riding one deck:
    the neighbour's estimate's error), and a row fully in at once would make up that half in one
    tick, a jump of the command. Phased in, the previous command meets the row at the latch and
    the row asks for ``w`` of the rest each tick; a new approach (the command turning towards a
    neighbour) is refused in full from the first tick. None, or a time past the phase-in: the
    rows as above, the same arrays."""
    if cfg.separation_m is None or not len(neighbours):
        return None
    pos, vel, fresh = neighbours.now(cfg.neighbour_max_age_s)
    if fresh is not None and not fresh.any():
        return None
    diff = x[..., None, :] - pos
    weighted = diff  # W (x - p_j)
    if diff.shape[-1] == 3 and cfg.separation_vertical_ratio != 1.0:
        w_z = np.full(diff.shape[:-1], cfg.separation_vertical_ratio ** -2)
        if neighbours.on_deck is not None:
            w_z = np.where(np.asarray(neighbours.on_deck, dtype=bool), 1.0, w_z)  # the deck's obstacles: a sphere
        weighted = np.concatenate([diff[..., :2], (diff[..., 2] * w_z)[..., None]], axis=-1)
    dist2 = dot(weighted, diff)
    keep2 = cfg.separation_m**2 if neighbours.distance_m is None else np.asarray(neighbours.distance_m, dtype=float) ** 2
    h = dist2 - np.minimum(keep2, dist2)
    A = 2.0 * weighted
    b = dot(weighted, own_velocity[..., None, :] + vel) - 0.5 * cfg.cbf_gain * h
    if since_separation_s is not None and cfg.separation_phase_in_s > 0:
        w = phase_in_weight(since_separation_s, cfg.separation_phase_in_s)
        if np.any(w < 1.0):
            lack = np.maximum(b - dot(A, own_velocity[..., None, :]), 0.0)
            b = b - (1.0 - w)[..., None] * lack
    if fresh is not None:
        A, b = np.where(fresh[..., None], A, 0.0), np.where(fresh, b, -1.0)
    return A, b


def veer_right(u: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The tie-break of a symmetric meeting: where ``u`` (..., n) breaks a neighbour's row, add
    :data:`TIE_BREAK` ``|u|`` in the horizontal plane, :data:`VEER_RAD` to the right of the
    direction to that neighbour (NED x north, y east: right of north is east), i.e. to the right
    and a little back. Both of a head-on pair veer to their own right and pass each other, and
    three that meet in the middle turn round it one way, where the barrier alone would stop them
    face to face for good (it lets no one of a pair at ``D`` approach the other, and the law
    pulls straight ahead). The slight backing off is what frees three already packed at ``D``:
    purely to the right (90 deg) 2 to 5 of 200 such 2D scenarios stayed stuck (docs/team.md)."""
    breaks = dot(A, u[..., None, :]) < b
    if not breaks.any():
        return u
    to = -A / np.maximum(norm(A), 1e-300)[..., None]
    right = np.zeros(A.shape)
    c, s_ = np.cos(VEER_RAD), np.sin(VEER_RAD)
    right[..., 0], right[..., 1] = c * to[..., 0] - s_ * to[..., 1], s_ * to[..., 0] + c * to[..., 1]
    push = np.sum(np.where(breaks[..., None], right, 0.0), axis=-2)
    return u + TIE_BREAK * norm(u)[..., None] * push


def limit_speed_keeping(u: np.ndarray, max_speed_m_s: float, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`limit_speed`, but no slower than the rows ``A u >= b`` with ``b > 0`` allow (a
    neighbour flying at this passenger: scaling towards zero would break its row)."""
    mag = norm(u)
    scale = np.minimum(1.0, max_speed_m_s / np.maximum(mag, 1e-300))
    au = dot(A, u[..., None, :])
    need = np.max(np.where((b > 0) & (au > 0), b / np.where(au > 0, au, 1.0), 0.0), axis=-1)
    return u * np.maximum(scale, np.minimum(need, 1.0))[..., None]


@dataclass(frozen=True)
class DeckKeepOut:
    """The keep-out round the carrier's deck (3D, NED): everything low beside it.

    centre_ned_m [m]: the deck's centre on its plane (the dock point); velocity_ned_m_s [m/s]: the
    deck's; radius_m [m]: the funnel's radius on the deck; slope [-]: metres it widens per metre of
    height; clear_height_m [m]: above this height over the deck the keep-out ends. The barrier acts
    only inside the funnel's extent (below ``clear_height_m`` and within the rim's radius
    ``radius_m + slope * clear_height_m``), so a passenger far from the deck never feels it."""

    centre_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    radius_m: float
    slope: float
    clear_height_m: float

    SMOOTH_M = 0.02  # [m] the horizontal distance is smoothed by this near the axis (a gradient everywhere)

    def height_m(self, x: np.ndarray) -> np.ndarray:
        """Height [m] of ``x`` (..., 3) NED above the deck's plane."""
        return self.centre_ned_m[2] - x[..., 2]

    def row(self, x: np.ndarray, gain: float) -> tuple[np.ndarray, np.ndarray]:
        """The constraint ``A u >= b`` at ``x`` (..., 3): A (..., 3), b (...); a row that always
        holds (0 >= -1) outside the keep-out's extent."""
        off = x[..., :2] - self.centre_ned_m[:2]
        r = np.sqrt(dot(off, off) + self.SMOOTH_M**2)
        height = self.height_m(x)
        above = height >= 0.0  # below the deck's plane (pressed into it on landing) only the radius holds
        h = self.radius_m + self.slope * np.maximum(height, 0.0) - r
        grad = np.empty(x.shape)
        grad[..., :2] = -off / r[..., None]
        grad[..., 2] = np.where(above, -self.slope, 0.0)  # NED: climbing (u_z < 0) raises h
        b = dot(grad, np.broadcast_to(self.velocity_ned_m_s, x.shape)) - gain * h
        near = (height < self.clear_height_m) & (r < self.radius_m + self.slope * self.clear_height_m)
        return np.where(near[..., None], grad, 0.0), np.where(near, b, -1.0)


@dataclass(frozen=True)
class FilterResult:
    """Output of :func:`filter_velocity` (arrays broadcast like the input's leading shape).

    u [m/s] the safe command; changed: the filter changed the command; correction_m_s: ``|u -
    u_des|``; feasible: the CBF-QP had a solution (else ``u`` is the zero-velocity fallback);
    cbf_active: a barrier constraint was active.
    """

    u: np.ndarray
    changed: np.ndarray
    correction_m_s: np.ndarray
    feasible: np.ndarray
    cbf_active: np.ndarray


def _bound_rows(cfg: SafetyConfig, n: int) -> tuple[tuple[tuple[float, float], ...], np.ndarray]:
    """The active bounds on the third coordinate as ((bound [m], sign), ...) and their constant
    constraint rows (k, n): ``sign * e_z`` (built once per configuration and n, read-only)."""
    cached = cfg._cache.get(n)
    if cached is None:
        bounds = tuple((bound, sign) for bound, sign in ((cfg.z_min_m, 1.0), (cfg.z_max_m, -1.0))
                       if bound is not None and n >= 3)
        rows = np.zeros((len(bounds), n))
        for i, (_, sign) in enumerate(bounds):
            rows[i, 2] = sign
        rows.setflags(write=False)
        cached = cfg._cache[n] = (bounds, rows)
    return cached


def barrier_constraints(x: np.ndarray, obstacles: Obstacles, cfg: SafetyConfig,
                        deck: DeckKeepOut | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Linear constraints ``A u >= b`` of the CBF condition at ``x``: A (..., m, n), b (..., m).

    Rows: the obstacles first, then the lower and the upper bound on the third coordinate, then
    the deck's keep-out (if any).
    """
    if deck is not None:
        A0, b0 = barrier_constraints(x, obstacles, cfg)
        a_deck, b_deck = deck.row(x, cfg.cbf_gain)
        return np.concatenate([A0, a_deck[..., None, :]], axis=-2), np.concatenate([b0, b_deck[..., None]], axis=-1)
    n = x.shape[-1]
    lead = x.shape[:-1]
    bounds, bound_rows = _bound_rows(cfg, n)
    m = len(obstacles)
    if obstacles.centers.ndim > 2:  # per-scenario obstacles (B, m, n)
        lead = np.broadcast_shapes(lead, obstacles.centers.shape[:-2])
    A = np.empty(lead + (m + len(bounds), n))
    b = np.empty(lead + (m + len(bounds),))
    if m:
        diff = x[..., None, :] - obstacles.centers
        h = dot(diff, diff) - obstacles.keepout_sq(cfg.margin_m)
        np.multiply(2.0, diff, out=A[..., :m, :])
        np.multiply(-cfg.cbf_gain, h, out=b[..., :m])
    if bounds:
        A[..., m:, :] = bound_rows
        for i, (bound, sign) in enumerate(bounds):
            b[..., m + i] = -cfg.cbf_gain * sign * (x[..., 2] - bound)
    return A, b


def _solve_qp(u_des: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """min |u - u_des|^2 s.t. A u >= b for one vector, by DAQP; None if infeasible."""
    n = u_des.shape[0]
    upper = np.full(b.shape, 1e30)
    u, _, exitflag, _ = daqp.solve(np.eye(n), -u_des.astype(float), np.ascontiguousarray(A, dtype=float), upper, b.astype(float))
    return np.asarray(u, dtype=float) if exitflag >= 1 else None


def project_cbf(u_des: np.ndarray, A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares correction of ``u_des`` (..., n) onto ``A u >= b``.

    Returns (u, feasible, active); ``u`` is a new array. Closed form when exact, DAQP for the
    rows that need it.
    """
    # (np.logical_*.reduce and np.count_nonzero instead of .any()/.all()/.sum(): same results,
    # a fraction of the call overhead, which dominates for one vector.)
    u = np.asarray(u_des, dtype=float)
    lead = u.shape[:-1]
    feasible = np.empty(lead, dtype=bool)
    feasible.fill(True)
    if A.shape[-2] == 0:
        return u.copy(), feasible, np.zeros(lead, dtype=bool)
    slack = dot(A, u[..., None, :]) - b
    violated = slack < -_TOL
    active = np.logical_or.reduce(violated, axis=-1)
    n_active = np.count_nonzero(active)
    if not n_active:
        return u.copy(), feasible, active
    # Candidate projections onto each violated constraint, then keep one satisfying all others.
    a2 = dot(A, A)
    step = np.where(violated, -slack / np.maximum(a2, 1e-300), 0.0)
    tol = -1e-7 * (1.0 + np.abs(b))
    if np.count_nonzero(violated) == n_active:
        # Common case, one violated constraint per vector: its projection is the only candidate.
        # step is zero on the other rows, so the product step A is exactly step_j * A_j.
        chosen = u + (step[..., None, :] @ A)[..., 0, :]
        has = np.logical_and.reduce(dot(A, chosen[..., None, :]) - b >= tol, axis=-1)
        positive = a2 > 0
        if np.count_nonzero(positive) < positive.size:  # a zero row is never a valid candidate
            has &= np.logical_and.reduce(positive | ~violated, axis=-1)
    else:
        cand = u[..., None, :] + step[..., None] * A  # (..., m, n)
        cand_slack = dot(A[..., None, :, :], cand[..., :, None, :]) - b[..., None, :]  # (..., m cand, k cons)
        ok = violated & np.logical_and.reduce(cand_slack >= tol[..., None, :], axis=-1) & (a2 > 0)
        has = np.logical_or.reduce(ok, axis=-1)
        first = np.argmax(ok, axis=-1)
        chosen = np.take_along_axis(cand, first[..., None, None], axis=-2)[..., 0, :]
    take = active & has
    u = np.where(take[..., None], chosen, u) if take.ndim else (chosen if take else u.copy())
    need_qp = active & ~has
    if np.count_nonzero(need_qp):
        for idx in zip(*np.nonzero(need_qp)) if lead else [()]:
            sol = _solve_qp(u_des[idx], A[idx], b[idx])
            if sol is None:
                u[idx] = 0.0
                feasible[idx] = False
            else:
                u[idx] = sol
    return u, feasible, active


def limit_accel(u: np.ndarray, u_prev: np.ndarray, max_accel_m_s2: float, dt_s: float) -> np.ndarray:
    """Limit the change ``u - u_prev`` [m/s] to ``max_accel * dt`` along its own direction."""
    du = u - u_prev
    mag = norm(du)
    scale = np.minimum(1.0, max_accel_m_s2 * dt_s / np.maximum(mag, 1e-300))
    return u_prev + du * scale[..., None]


def limit_speed(u: np.ndarray, max_speed_m_s: float) -> np.ndarray:
    """Scale ``u`` [m/s] down to at most ``max_speed`` keeping its direction.

    Returns ``u`` itself when no vector is too fast (the scale would be exactly 1)."""
    mag = norm(u)
    if (mag <= max_speed_m_s).all():
        return u
    scale = np.minimum(1.0, max_speed_m_s / np.maximum(mag, 1e-300))
    return u * scale[..., None]


def filter_velocity(
    x: np.ndarray,
    u_des: np.ndarray,
    obstacles: Obstacles,
    cfg: SafetyConfig,
    u_prev: np.ndarray | None = None,
    dt_s: float | None = None,
    *,
    copy: bool = True,
    deck: DeckKeepOut | None = None,
    neighbours: Neighbours | None = None,
    since_separation_s: float | np.ndarray | None = None,
) -> FilterResult:
    """Safe velocity near ``u_des`` at position ``x`` (arrays ``(..., n)``); see module doc.

    ``u_prev`` [m/s] and ``dt_s`` [s] enable the acceleration limit; ``deck``: the keep-out round
    a moving deck (3D); ``neighbours``: the other passengers (:func:`neighbour_rows`, whose own
    velocity is ``u_prev``, else ``u_des``; a blocked head-on meeting veers right first,
    :func:`veer_right`, before the acceleration limit); ``since_separation_s`` [s]: the time
    since this passenger separated, over which those rows phase in (None: fully in). ``u`` of the result is a
    new array, except with ``copy=False`` when nothing changed the command: then it is
    ``u_des`` itself (for callers that own ``u_des`` and never write into either).
    """
    u_des = np.asarray(u_des, dtype=float)
    u = u_des
    pair = None if neighbours is None else neighbour_rows(
        np.asarray(x, dtype=float), u_des if u_prev is None else np.asarray(u_prev, dtype=float), neighbours, cfg,
        since_separation_s)
    if pair is not None:
        u = veer_right(u, *pair)
    if cfg.max_accel_m_s2 is not None and u_prev is not None and dt_s is not None:
        u = limit_accel(u, u_prev, cfg.max_accel_m_s2, dt_s)
    if pair is not None:
        A, b = barrier_constraints(np.asarray(x, dtype=float), obstacles, cfg, deck)
        lead = np.broadcast_shapes(A.shape[:-2], pair[0].shape[:-2])
        A = np.concatenate([np.broadcast_to(A, lead + A.shape[-2:]), np.broadcast_to(pair[0], lead + pair[0].shape[-2:])], axis=-2)
        b = np.concatenate([np.broadcast_to(b, lead + b.shape[-1:]), np.broadcast_to(pair[1], lead + pair[1].shape[-1:])], axis=-1)
        u, feasible, active = project_cbf(u, A, b)
        if cfg.max_speed_m_s is not None:
            u = limit_speed_keeping(u, cfg.max_speed_m_s, *pair)
    elif len(obstacles) or _bound_rows(cfg, u.shape[-1])[0] or deck is not None:
        A, b = barrier_constraints(np.asarray(x, dtype=float), obstacles, cfg, deck)
        u, feasible, active = project_cbf(u, A, b)
    else:  # no barrier at all
        feasible = np.empty(u.shape[:-1], dtype=bool)
        feasible.fill(True)
        active = np.zeros(u.shape[:-1], dtype=bool)
    if cfg.max_speed_m_s is not None and pair is None:
        u = limit_speed(u, cfg.max_speed_m_s)
    if u is u_des:  # no limit and no barrier applied: the command passes unchanged
        unchanged = np.zeros(u.shape[:-1])[()]  # (a numpy scalar for one vector, as norm gives)
        return FilterResult(u=u.copy() if copy else u, changed=unchanged > 0.0, correction_m_s=unchanged,
                            feasible=feasible, cbf_active=active)
    correction = norm(u - u_des)
    return FilterResult(u=u, changed=correction > CHANGED_M_S, correction_m_s=correction, feasible=feasible, cbf_active=active)
