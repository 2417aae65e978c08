"""The equilibrium-driven law of Hu, Jayawardhana and Cao (pure, numpy).

Every function takes arrays of shape ``(..., n)`` (n = 2 or 3, any leading batch shape), so the
same code serves one realtime tick (shape ``(n,)``) and a batch of thousands of scenarios
(shape ``(B, n)``). Units are SI: positions [m], velocities [m/s], gains [1/s] or as noted.
The frame is whatever frame the caller works in (the mission uses PX4's local NED).

Errors (paper eqs. 2-3)::

    e_pc = x_p - x_c      e_tc = x_t - x_c      e_pt = x_p - x_t = e_pc - e_tc

Potential gradient (eq. 6), a cubic in ``a = |e_pc|`` with ``L = |e_tc|``::

    P = k_p (a - L)(a + d)(a - L/b + c)

Passenger (eq. 5): ``u_p = -P e_pc + u_c`` if ``P >= 0`` (equilibrium i: stay docked) else
``u_p = P e_pt + u_c`` (leave towards the target, equilibrium iii). Carrier (eq. 4):
``u_c = k_c e_tc`` while docked, else 0. The relative input ``u_p - u_c`` is continuous across
``P = 0`` because both branches vanish there: that is the smooth separation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mission.errors import AssumptionError, ConfigError


@dataclass(frozen=True)
class LawParams:
    """Gains and shape parameters of the law (paper values by default).

    k_c [1/s] carrier gain; k_p [1/m^3/s... ] passenger gain (P has units 1/s when
    multiplied by distances); b > 1 [-]; c [m]; d [m]. Separation happens when the docked
    carrier comes within ``b * c`` [m] of the target.
    """

    k_c: float = 0.5
    k_p: float = 1.0
    b: float = 8.0
    c: float = 1.0
    d: float = 1.0

    def __post_init__(self) -> None:
        for name in ("k_c", "k_p", "c", "d"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ConfigError(f"law.{name}", value, "must be a finite number > 0")
        if not (np.isfinite(self.b) and self.b > 1):
            raise ConfigError("law.b", self.b, "must be > 1 (paper eq. 7)")

    @property
    def separation_distance_m(self) -> float:
        """Carrier-target distance ``b c`` [m] at which the docked passenger separates."""
        return self.b * self.c


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot product over the last axis (operands broadcast), shape ``(...)``; units: product of both.

    For n = 2 and 3 (our vectors) the sum is written out, which is cheaper than ``np.einsum`` both
    for one vector and for (10 000, 3) batches. The summation order is fixed to the one einsum
    used, ``(a0 b0 + a2 b2) + a1 b1``, so results are bit-for-bit those of einsum.
    """
    a, b = np.asanyarray(a), np.asanyarray(b)
    n = a.shape[-1]
    if n == 3:
        p = a * b
        return (p[..., 0] + p[..., 2]) + p[..., 1]
    if n == 2:
        p = a * b
        return p[..., 0] + p[..., 1]
    return np.einsum("...i,...i->...", a, b)


def norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norm over the last axis, shape ``(...)`` (same unit as ``v``).

    One float vector of length 2 or 3 (the realtime tick) is reduced with Python floats: a tenth
    of numpy's per-call overhead, and the same IEEE operations in the same order as :func:`dot`.
    """
    v = np.asanyarray(v)
    if v.ndim == 1 and v.shape[0] in (2, 3) and v.dtype == np.float64:
        c = v.tolist()
        s = c[0] * c[0] + c[1] * c[1] if len(c) == 2 else (c[0] * c[0] + c[2] * c[2]) + c[1] * c[1]
        return np.float64(math.sqrt(s))
    return np.sqrt(dot(v, v))


def uniform(mask: np.ndarray) -> bool | None:
    """``True``/``False`` when every element of the boolean ``mask`` has that value, ``None`` when
    they differ. Lets batch code skip an element-wise select when a whole batch (or the one
    realtime vector) takes the same branch."""
    if mask.ndim == 0:
        return bool(mask)
    count = np.count_nonzero(mask)  # (cheaper per call than .any() and .all())
    if count == 0:
        return False
    return True if count == mask.size else None


def where_rows(mask: np.ndarray, a: np.ndarray | float, b: np.ndarray) -> np.ndarray | float:
    """``np.where(mask[..., None], a, b)`` for a mask over the leading axes of vectors (..., n).

    When the mask is uniform, ``a`` or ``b`` itself is returned (no copy, no broadcast): use the
    result in arithmetic only, never write into it.
    """
    branch = uniform(mask)
    if branch is None:
        return np.where(mask[..., None], a, b)
    return a if branch else b


def potential(a: np.ndarray, L: np.ndarray, p: LawParams) -> np.ndarray:
    """Potential gradient P [1/s] from distances ``a = |e_pc|`` and ``L = |e_tc|`` [m]."""
    return p.k_p * (a - L) * (a + p.d) * (a - L / p.b + p.c)


@dataclass(frozen=True)
class PassengerCommand:
    """Result of :func:`passenger_command`.

    u_p [m/s] passenger velocity; relative [m/s] ``u_p - u_c``; P [1/s] the potential gradient;
    leaving (bool) true where the separating branch ``P < 0`` is active; e_pc_norm_m [m] the
    passenger-anchor distance ``|e_pc|`` the law used (returned so callers need not recompute it).
    """

    u_p: np.ndarray
    relative: np.ndarray
    P: np.ndarray
    leaving: np.ndarray
    e_pc_norm_m: np.ndarray


def passenger_command(
    e_pc: np.ndarray,
    e_tc: np.ndarray,
    u_c: np.ndarray,
    p: LawParams,
    e_tc_norm: np.ndarray | float | None = None,
) -> PassengerCommand:
    """Passenger velocity command, paper eq. 5.

    e_pc, e_tc [m], u_c [m/s]: arrays ``(..., n)``. ``u_c`` is the carrier velocity the passenger
    feeds forward (the carrier command while docked; zero after separation).
    ``e_tc_norm`` [m] overrides ``|e_tc|`` in P (Remark 1: the distance latched at separation).
    """
    a = norm(e_pc)
    L = norm(e_tc) if e_tc_norm is None else np.asarray(e_tc_norm, dtype=float)
    P = potential(a, L, p)
    leaving = P < 0
    branch = uniform(leaving)
    if branch is None:  # a batch with both branches active
        gain = np.where(leaving, P, -P)[..., None]
        relative = gain * np.where(leaving[..., None], e_pc - e_tc, e_pc)
    elif branch:  # every vector leaves: u_p - u_c = P e_pt
        relative = P[..., None] * (e_pc - e_tc)
    else:  # every vector stays docked: u_p - u_c = -P e_pc
        relative = (-P)[..., None] * e_pc
    return PassengerCommand(u_p=relative + u_c, relative=relative, P=P, leaving=leaving, e_pc_norm_m=a)


def carrier_command(e_tc: np.ndarray, docked: np.ndarray | bool, p: LawParams, planar: bool = False) -> np.ndarray:
    """Carrier velocity command [m/s], paper eq. 4: ``k_c e_tc`` while docked, else 0.

    ``planar``: the carrier moves in the plane of the first two axes (3D figure of the paper:
    the command is computed in 3D and its third component set to zero).
    """
    u = p.k_c * e_tc  # a new array: the zeroing below works in place
    docked = np.asarray(docked, dtype=bool)
    if uniform(docked) is not True:  # multiplying by 1.0 changes nothing: skip it when all docked
        u *= docked[..., None]
    if planar and u.shape[-1] >= 3:
        u[..., 2:] = 0.0
    return u


def project_planar(v: np.ndarray) -> np.ndarray:
    """Copy of ``v`` with the third axis set to zero (no-op for 2D arrays)."""
    if v.shape[-1] < 3:
        return v
    out = np.array(v, dtype=float, copy=True)
    out[..., 2:] = 0.0
    return out


def check_assumptions(
    carrier_start: np.ndarray,
    target: np.ndarray,
    p: LawParams,
    *,
    planar_carrier: bool = False,
    eta: float | None = None,
    passenger_start: np.ndarray | None = None,
    dock_tolerance_m: float = 0.0,
    field_prefix: str = "scenario",
) -> None:
    """Raise :class:`AssumptionError` if the geometry breaks the paper's assumptions.

    Checks ``b c < eta <= |e_tc(0)|`` (Assumption 1 and eq. 7, ``eta`` defaults to
    ``|e_tc(0)|``), the passenger starting on the carrier (Assumption 2, within
    ``dock_tolerance_m``), and, with a planar carrier in 3D, that the target's height above the
    carrier's plane is ``<= b c`` (otherwise ``|e_tc|`` never reaches ``b c`` and the passenger
    never separates).
    """
    carrier_start = np.asarray(carrier_start, dtype=float)
    target = np.asarray(target, dtype=float)
    bc = p.separation_distance_m
    dist = float(norm(target - carrier_start))
    eta_v = dist if eta is None else float(eta)
    if not bc < eta_v:
        raise AssumptionError(f"{field_prefix}.eta", eta_v, f"must exceed b*c = {bc:g} m (paper eq. 7)")
    if not eta_v <= dist + 1e-9:
        raise AssumptionError(
            f"{field_prefix}.carrier_start",
            carrier_start.tolist(),
            f"carrier-target distance {dist:.3f} m must be >= eta = {eta_v:g} m (Assumption 1)",
        )
    if passenger_start is not None:
        gap = float(norm(np.asarray(passenger_start, dtype=float) - carrier_start))
        if gap > dock_tolerance_m:
            raise AssumptionError(
                f"{field_prefix}.passenger_start",
                np.asarray(passenger_start).tolist(),
                f"passenger must start on the carrier (gap {gap:.3f} m > tolerance {dock_tolerance_m:g} m, Assumption 2)",
            )
    if planar_carrier and carrier_start.shape[-1] == 3:
        height = abs(float(target[2] - carrier_start[2]))
        if height > bc:
            raise AssumptionError(
                f"{field_prefix}.target",
                target.tolist(),
                f"height {height:.3f} m above the carrier's plane must be <= b*c = {bc:g} m, "
                "or the planar carrier never gets close enough to separate",
            )
