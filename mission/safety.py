"""Safety filter (pure, numpy): CBF-QP obstacle and altitude constraints, accel and speed limits.

A desired velocity ``u_des`` [m/s] at position ``x`` [m] (arrays ``(..., n)``) is changed as
little as possible (least squares) so that every barrier stays non-negative:

- obstacle i (circle in 2D, sphere in 3D): ``h_i = |x - o_i|^2 - (r_i + margin)^2``,
  constraint ``dh_i/dt = 2 (x - o_i) . u >= -gain * h_i``;
- optional bounds on the third coordinate (``z_min_m <= z <= z_max_m``; in PX4's NED frame
  an altitude floor of 2 m is ``z_max_m = -2``): ``+-u_z >= -gain * (distance to the bound)``.

The QP is solved in closed form where that is exact (no constraint violated, or a projection on
one violated constraint that satisfies all others: it meets the KKT conditions, so it is the
optimum) and by DAQP otherwise. If the QP is infeasible the fallback is zero velocity (hold
position) and ``feasible`` is false.

Order: the change of command is first limited to ``max_accel_m_s2 * dt_s`` (along the change),
then the barriers act, then the speed is limited to ``max_speed_m_s`` by scaling (the direction is
kept, and scaling towards zero never breaks a satisfied barrier constraint). So the barriers have
the last word: when an obstacle demands a harder stop than the acceleration limit allows, safety
wins over comfort (``cbf_active`` says so).
"""
from __future__ import annotations

from dataclasses import dataclass

import daqp
import numpy as np

from mission.law import norm

_TOL = 1e-9


@dataclass(frozen=True)
class Obstacles:
    """Circular (2D) or spherical (3D) obstacles: centers [m] shape (m, n) (or (B, m, n) for a
    batch with per-scenario obstacles), radii [m] shape (m,)."""

    centers: np.ndarray
    radii: np.ndarray

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
        return int(self.radii.shape[0])

    def planar(self) -> "Obstacles":
        """The same obstacles seen by a planar robot: their first two coordinates (circles)."""
        return Obstacles(self.centers[..., :2], self.radii)

    def clearance(self, x: np.ndarray) -> np.ndarray:
        """Distance [m] from ``x`` (..., n) to each obstacle's surface: shape (..., m)."""
        diff = x[..., None, :] - self.centers
        return norm(diff) - self.radii


@dataclass(frozen=True)
class SafetyConfig:
    """Parameters of the filter. None disables a limit.

    cbf_gain [1/s] class-K gain; margin_m [m] added to every radius; max_speed_m_s [m/s];
    max_accel_m_s2 [m/s^2]; z_min_m / z_max_m [m] bounds on the third coordinate.
    """

    cbf_gain: float = 1.0
    margin_m: float = 0.5
    max_speed_m_s: float | None = None
    max_accel_m_s2: float | None = None
    z_min_m: float | None = None
    z_max_m: float | None = None


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


def barrier_constraints(x: np.ndarray, obstacles: Obstacles, cfg: SafetyConfig) -> tuple[np.ndarray, np.ndarray]:
    """Linear constraints ``A u >= b`` of the CBF condition at ``x``: A (..., m, n), b (..., m)."""
    n = x.shape[-1]
    rows_A, rows_b = [], []
    if len(obstacles):
        diff = x[..., None, :] - obstacles.centers
        h = np.einsum("...i,...i->...", diff, diff) - (obstacles.radii + cfg.margin_m) ** 2
        rows_A.append(2.0 * diff)
        rows_b.append(-cfg.cbf_gain * h)
    for bound, sign in ((cfg.z_min_m, 1.0), (cfg.z_max_m, -1.0)):
        if bound is None or n < 3:
            continue
        a = np.zeros(x.shape[:-1] + (1, n))
        a[..., 0, 2] = sign
        rows_A.append(a)
        rows_b.append((-cfg.cbf_gain * sign * (x[..., 2] - bound))[..., None])
    if not rows_A:
        return np.zeros(x.shape[:-1] + (0, n)), np.zeros(x.shape[:-1] + (0,))
    return np.concatenate(rows_A, axis=-2), np.concatenate(rows_b, axis=-1)


def _solve_qp(u_des: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """min |u - u_des|^2 s.t. A u >= b for one vector, by DAQP; None if infeasible."""
    n = u_des.shape[0]
    upper = np.full(b.shape, 1e30)
    u, _, exitflag, _ = daqp.solve(np.eye(n), -u_des.astype(float), np.ascontiguousarray(A, dtype=float), upper, b.astype(float))
    return np.asarray(u, dtype=float) if exitflag >= 1 else None


def project_cbf(u_des: np.ndarray, A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares correction of ``u_des`` (..., n) onto ``A u >= b``.

    Returns (u, feasible, active). Closed form when exact, DAQP for the rows that need it.
    """
    u = np.array(u_des, dtype=float, copy=True)
    lead = u.shape[:-1]
    feasible = np.ones(lead, dtype=bool)
    if A.shape[-2] == 0:
        return u, feasible, np.zeros(lead, dtype=bool)
    slack = np.einsum("...mi,...i->...m", A, u) - b
    violated = slack < -_TOL
    active = violated.any(axis=-1)
    if not active.any():
        return u, feasible, active
    # Candidate projections onto each violated constraint, then keep one satisfying all others.
    a2 = np.einsum("...mi,...mi->...m", A, A)
    step = np.where(violated, -slack / np.maximum(a2, 1e-300), 0.0)
    cand = u[..., None, :] + step[..., None] * A  # (..., m, n)
    cand_slack = np.einsum("...kj,...mj->...mk", A, cand) - b[..., None, :]  # (..., m cand, k cons)
    ok = violated & (cand_slack >= -1e-7 * (1.0 + np.abs(b[..., None, :]))).all(axis=-1) & (a2 > 0)
    has = ok.any(axis=-1)
    first = np.argmax(ok, axis=-1)
    chosen = np.take_along_axis(cand, first[..., None, None], axis=-2)[..., 0, :]
    u = np.where((active & has)[..., None], chosen, u)
    need_qp = active & ~has
    if need_qp.any():
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
    """Scale ``u`` [m/s] down to at most ``max_speed`` keeping its direction."""
    mag = norm(u)
    scale = np.minimum(1.0, max_speed_m_s / np.maximum(mag, 1e-300))
    return u * scale[..., None]


def filter_velocity(
    x: np.ndarray,
    u_des: np.ndarray,
    obstacles: Obstacles,
    cfg: SafetyConfig,
    u_prev: np.ndarray | None = None,
    dt_s: float | None = None,
) -> FilterResult:
    """Safe velocity near ``u_des`` at position ``x`` (arrays ``(..., n)``); see module doc.

    ``u_prev`` [m/s] and ``dt_s`` [s] enable the acceleration limit.
    """
    u_des = np.asarray(u_des, dtype=float)
    u = u_des
    if cfg.max_accel_m_s2 is not None and u_prev is not None and dt_s is not None:
        u = limit_accel(u, u_prev, cfg.max_accel_m_s2, dt_s)
    A, b = barrier_constraints(np.asarray(x, dtype=float), obstacles, cfg)
    u, feasible, active = project_cbf(u, A, b)
    if cfg.max_speed_m_s is not None:
        u = limit_speed(u, cfg.max_speed_m_s)
    correction = norm(u - u_des)
    return FilterResult(u=u, changed=correction > 1e-12, correction_m_s=correction, feasible=feasible, cbf_active=active)
