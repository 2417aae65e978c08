"""A seeded world for the relative estimator's tests and bench: the truth, what the sensors measured and when
each measurement arrives (units SI, NED, seconds).

The truth follows the estimator's own model (:mod:`mission.relnav.kalman`): the carrier's position
and velocity in the passenger's frame a constant velocity driven by white acceleration, the
GNSS-frame bias a first-order Gauss-Markov process (or held constant), so that its covariance can
be checked against the errors (NEES). The passenger flies a circle (its own state an input of
the estimator); the relative position is the carrier's less the passenger's.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from mission.relnav.estimator import RelativeEstimator, RelnavParams
from mission.relnav.inputs import CarrierFix, MarkerFix, OwnSample, RelativeEstimate


@dataclass
class World:
    """One run: ``ticks`` (the passenger's samples), ``truth`` (9,) per tick (the relative position,
    the relative velocity, the bias), ``arrivals``
    (arrival time [s], measurement) sorted by arrival."""

    ticks: list[OwnSample] = field(default_factory=list)
    truth: list[np.ndarray] = field(default_factory=list)
    arrivals: list[tuple[float, object]] = field(default_factory=list)


def make_world(params: RelnavParams, seed: int, *, duration_s: float = 30.0, dt_s: float = 0.05,
               gnss_every: int = 2, marker_every: int = 2, marker_from_s: float = math.inf,
               marker_sigma_m: float = 0.03, constant_bias_m: tuple[float, float, float] | None = None,
               marker_delay_s: tuple[float, float] = (0.05, 0.15), gnss_delay_s: tuple[float, float] = (0.1, 0.3),
               prior: bool = False, measure_until_s: float = math.inf, truth_accel_m_s2: float | None = None) -> World:
    """The world of ``params``'s model, seeded. ``prior``: the carrier's initial state drawn from the
    estimator's prior (for a consistency check); else a fixed start 10 m from the passenger, at its
    velocity. Markers
    (isotropic ``marker_sigma_m``) from ``marker_from_s`` on; each measurement arrives a uniform
    delay in its range after it is taken; none is taken after ``measure_until_s``.
    ``truth_accel_m_s2``: the truth's carrier acceleration noise (default: the model's)."""
    rng = np.random.default_rng(seed)
    q = (params.accel_noise_m_s2 if truth_accel_m_s2 is None else truth_accel_m_s2) ** 2
    chol = np.linalg.cholesky(q * np.array([[dt_s ** 3 / 3, dt_s ** 2 / 2], [dt_s ** 2 / 2, dt_s]]))
    decay = math.exp(-dt_s / params.bias_tau_s)
    axes = np.array([1.0, 1.0, params.vertical_factor])  # the vertical sigmas over the horizontal ones
    bias_sigma = params.bias_sigma_m * axes
    kick = bias_sigma * math.sqrt(1 - decay ** 2)
    def own(t: float) -> tuple[np.ndarray, np.ndarray]:
        return (np.array([20 * math.cos(0.1 * t), 20 * math.sin(0.1 * t), -5.0]),
                np.array([-2 * math.sin(0.1 * t), 2 * math.cos(0.1 * t), 0.0]))

    if prior:  # the carrier's position c and velocity u in the passenger's frame
        c = rng.normal(0, params.initial_sigma_m, 3)
        u = rng.normal(0, params.initial_velocity_sigma_m_s, 3)
    else:
        c, u = own(0.0)[0] + np.array([10.0, -4.0, 1.0]), own(0.0)[1].copy()
    b = np.array(constant_bias_m, dtype=float) if constant_bias_m is not None else bias_sigma * rng.standard_normal(3)
    w = World()
    n = int(round(duration_s / dt_s))
    for k in range(n + 1):
        t = k * dt_s
        if k > 0:
            for axis in range(3):
                dc, du = chol @ rng.standard_normal(2)
                c[axis], u[axis] = c[axis] + dt_s * u[axis] + dc, u[axis] + du
            if constant_bias_m is None:
                b = decay * b + kick * rng.standard_normal(3)
        own_p, own_v = own(t)
        r, v = c - own_p, u - own_v
        w.ticks.append(OwnSample(t, own_p, own_v))
        w.truth.append(np.concatenate([r, v, b]))
        if t > measure_until_s:
            continue
        if k % gnss_every == 0:
            fix = CarrierFix(t, own_p + r + b + params.gnss_position_sigma_m * axes * rng.standard_normal(3),
                             own_v + v + rng.normal(0, params.gnss_velocity_sigma_m_s, 3))
            w.arrivals.append((t + rng.uniform(*gnss_delay_s), fix))
        if t >= marker_from_s and k % marker_every == 0:
            w.arrivals.append((t + rng.uniform(*marker_delay_s),
                               MarkerFix.isotropic(t, r + rng.normal(0, marker_sigma_m, 3), marker_sigma_m)))
    w.arrivals.sort(key=lambda a: a[0])
    return w


def feed(est: RelativeEstimator, arrival: tuple[float, object]) -> None:
    m = arrival[1]
    if isinstance(m, CarrierFix):
        est.carrier(m)
    else:
        est.marker(m)  # type: ignore[arg-type]


def fly(est: RelativeEstimator, world: World, *, extra: list[tuple[float, object]] = ()) -> list[RelativeEstimate]:
    """Run ``world`` (and ``extra`` arrivals) through ``est``: before each tick, every measurement
    that has arrived by then. Returns the estimate after each tick."""
    arrivals = sorted([*world.arrivals, *extra], key=lambda a: a[0])
    out, i = [], 0
    for own in world.ticks:
        while i < len(arrivals) and arrivals[i][0] <= own.t_s:
            feed(est, arrivals[i])
            i += 1
        out.append(est.tick(own))
    return out


#: [s] the times the covariance's consistency is checked at (:func:`average_nees`)
NEES_CHECKPOINTS_S = (1.0, 3.0, 5.0, 7.5, 10.0)


def average_nees(params: RelnavParams, runs: int) -> tuple[np.ndarray, np.ndarray]:
    """Over ``runs`` seeded runs of the estimator's own model (ticks and GNSS at 10 Hz, markers
    from 3 s, all late), the average normalised estimation error squared at each of
    :data:`NEES_CHECKPOINTS_S`: of the whole state (9 dof) and of the position alone (3 dof)."""
    n9, n3 = np.zeros(len(NEES_CHECKPOINTS_S)), np.zeros(len(NEES_CHECKPOINTS_S))
    for seed in range(runs):
        world = make_world(params, seed=100 + seed, marker_from_s=3.0, duration_s=10.0, dt_s=0.1, gnss_every=1,
                           marker_every=1, prior=True)
        est = fly(RelativeEstimator(params), world)
        for j, t in enumerate(NEES_CHECKPOINTS_S):
            k = int(round(t / 0.1))
            e = est[k]
            err = np.concatenate([e.position_ned_m, e.velocity_ned_m_s, e.bias_ned_m]) - world.truth[k]
            n9[j] += err @ np.linalg.solve(e.covariance[:9, :9], err) / runs
            n3[j] += err[:3] @ np.linalg.solve(e.covariance[:3, :3], err[:3]) / runs
    return n9, n3
