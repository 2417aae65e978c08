"""Where a robot that moves along its heading can go while it stops (pure): the P3 guard's model
of a diff-drive or Ackermann carrier (:mod:`mission.carrier.guard`).

In the plane, a robot at horizontal distance ``rho`` [m] from a point, its heading ``phi`` [rad]
off the line to it (0: facing it, pi: facing away), drives a path of length ``s`` [m] whose
curvature is at most ``1 / R`` (``R`` [m] its tightest turning radius; 0: it turns on the spot).
Along the path ``d rho / d sigma = -cos phi`` and ``d phi / d sigma >= -1 / R`` (steering
towards the point at its tightest; the line of sight only turns ``phi`` further away), so ``phi``
never falls faster than ``1 / R`` and the distance it closes is at most::

    C(phi, s) = integral_0^s cos(max(phi - sigma / R, 0)) d sigma
              = R (sin phi - sin(phi - s / R))        s <= R phi
              = R sin phi + s - R phi                   s >  R phi

whatever it steers: its stopping path, a turn in progress included, closes at most
``max(C, 0)``, and it then faces the point at no less than ``max(phi - s / R, 0)``.

A robot that cannot reverse (an Ackermann car in PX4's OFFBOARD: speed ``|v|``) and must later
turn away from the point it faces drives on while it turns: turning away at radius ``R_t`` [m]
from ``phi < pi / 2`` closes ``R_t (1 - sin phi)`` more (:func:`turn_away_m`), the *turn
reserve* the guard keeps for it.
"""
from __future__ import annotations

import math


def closing_m(phi_rad: float, path_m: float, radius_m: float) -> float:
    """``max(C(phi, s), 0)`` [m]: the most a path of length ``path_m`` [m] with turning radius >=
    ``radius_m`` [m] closes on a point ``phi_rad`` [rad] off its heading (module docstring)."""
    phi = min(max(phi_rad, 0.0), math.pi)
    if path_m <= 0.0:
        return 0.0
    if radius_m <= 0.0:
        return path_m
    turn = radius_m * phi  # path length [m] to face the point at the tightest turn
    if path_m <= turn:
        c = radius_m * (math.sin(phi) - math.sin(phi - path_m / radius_m))
    else:
        c = radius_m * math.sin(phi) + path_m - turn
    return max(c, 0.0)


def turn_away_m(phi_rad: float, reserve_m: float) -> float:
    """How much a robot that faces a point ``phi_rad`` [rad] off its heading closes on it while it
    turns away at radius ``reserve_m`` [m]: ``reserve_m (1 - sin phi)`` below ``pi / 2``, else 0."""
    phi = min(max(phi_rad, 0.0), math.pi)
    return reserve_m * (1.0 - math.sin(phi)) if phi < 0.5 * math.pi else 0.0


def stop_closing_m(phi_rad: float, path_m: float, radius_m: float, reserve_m: float) -> float:
    """Closing [m] of a stopping path of length ``path_m`` [m] (:func:`closing_m`) plus the turn
    away from where it may then face (:func:`turn_away_m`); nondecreasing in ``path_m``."""
    if path_m <= 0.0:
        end = phi_rad
    else:
        end = 0.0 if radius_m <= 0.0 else max(phi_rad - path_m / radius_m, 0.0)
    return closing_m(phi_rad, path_m, radius_m) + turn_away_m(end, reserve_m)


def allowed_path_m(phi_rad: float, clearance_m: float, radius_m: float, reserve_m: float) -> float:
    """The longest stopping path [m] whose closing (:func:`stop_closing_m`) stays within
    ``clearance_m`` [m]; 0 when even standing still breaks it (then the guard was already broken,
    or the robot cannot turn away in the room it has)."""
    if clearance_m <= 0.0 or stop_closing_m(phi_rad, 0.0, radius_m, reserve_m) > clearance_m:
        return 0.0
    lo, hi = 0.0, clearance_m + math.pi * radius_m + 1.0  # closing(hi) >= hi - pi R > clearance
    while hi - lo > 1e-4:  # bisection to 0.1 mm (lo is kept: on the safe side)
        mid = 0.5 * (lo + hi)
        if stop_closing_m(phi_rad, mid, radius_m, reserve_m) <= clearance_m:
            lo = mid
        else:
            hi = mid
    return lo
