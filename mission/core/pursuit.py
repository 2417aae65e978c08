"""A reference that chases a moving goal with bounded speed and acceleration (pure, numpy).

The recovery phases fly the passenger through a reference ``(x_ref, u_ref)``; each tick a phase
names a *goal* (a point with its own velocity, e.g. the carrier's dock point) and :func:`pursue`
moves the reference towards it: the reference's velocity relative to the goal points at the goal
with speed ``min(speed limit, gain * distance, sqrt(2 * accel * distance))`` (it brakes to arrive
at rest on the goal), and the reference's velocity changes by at most ``accel * dt`` per tick.

Invariants: ``|u_next - u_ref| <= accel_m_s2 * dt_s`` whatever the goal does, so a phase that
swaps one goal for another cannot make the reference's velocity jump; on a goal moving at a
constant velocity the reference converges to it with that velocity (velocity matched).

Arrays: positions [m] and velocities [m/s] of shape (..., n) (n = 3 in a flight, NED); a batch
of B references pursues B goals at once (the Monte-Carlo simulation).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PursuitLimits:
    """speed_m_s [m/s]: the reference's speed relative to the goal; accel_m_s2 [m/s^2]: the
    change of its (absolute) velocity; gain_per_s [1/s]: the pull per metre near the goal."""

    speed_m_s: float
    accel_m_s2: float
    gain_per_s: float = 1.0


def closing_speed(distance_m: np.ndarray, limits: PursuitLimits) -> np.ndarray:
    """Speed [m/s] at which the reference closes on a goal ``distance_m`` [m] away: the speed
    limit, the linear pull near the goal, and the speed from which the acceleration limit still
    stops it on the goal, whichever is least."""
    d = np.maximum(np.asarray(distance_m, dtype=float), 0.0)
    return np.minimum(np.minimum(limits.speed_m_s, limits.gain_per_s * d), np.sqrt(2.0 * limits.accel_m_s2 * d))


def pursue(x_ref: np.ndarray, u_ref: np.ndarray, goal_x: np.ndarray, goal_v: np.ndarray, limits: PursuitLimits,
           dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The reference one tick ``dt_s`` [s] later: ``(x_next [m], u_next [m/s])``.

    ``goal_x`` [m] and ``goal_v`` [m/s] are the goal now (its velocity is fed forward, so a moving
    goal is matched, not trailed by speed / gain)."""
    x_ref, u_ref = np.asarray(x_ref, dtype=float), np.asarray(u_ref, dtype=float)
    rel = np.asarray(goal_x, dtype=float) - x_ref
    dist = np.linalg.norm(rel, axis=-1, keepdims=True)
    unit = np.divide(rel, dist, out=np.zeros_like(rel), where=dist > 1e-9)
    desired = np.asarray(goal_v, dtype=float) + unit * closing_speed(dist, limits)
    du = desired - u_ref
    size = np.linalg.norm(du, axis=-1, keepdims=True)
    cap = limits.accel_m_s2 * dt_s
    du = np.where(size > cap, du * (cap / np.maximum(size, 1e-12)), du)
    u_next = u_ref + du
    return x_ref + u_next * dt_s, u_next
