"""The wander of PX4's position estimate (sim/vehicle/estimator.py), off by default."""
from __future__ import annotations

import math

import numpy as np
import pytest

from sim.vehicle.estimator import PX4_SITL_DRIFT_SIGMA_M_S, PX4_SITL_DRIFT_TAU_S, EstimateDrift, flown_on_estimate
from sim.vehicle.physics.multicopter import Command


def test_drift_rate_has_the_measured_spread_and_correlation_time():
    drift, dt = EstimateDrift(PX4_SITL_DRIFT_SIGMA_M_S, seed=3), 0.05
    rates = []
    for _ in range(80_000):  # 4000 s
        drift.advance(dt)
        rates.append(drift.rate[0])
    x = np.array(rates)
    assert x.std() == pytest.approx(PX4_SITL_DRIFT_SIGMA_M_S, rel=0.1)
    lag = round(PX4_SITL_DRIFT_TAU_S / dt)
    assert np.corrcoef(x[:-lag], x[lag:])[0, 1] == pytest.approx(math.exp(-1.0), abs=0.08)


def test_same_seed_same_wander_and_off_means_none():
    a, b, off = EstimateDrift(0.18, seed=7), EstimateDrift(0.18, seed=7), EstimateDrift(0.0, seed=7)
    for _ in range(1000):
        for d in (a, b, off):
            d.advance(0.005)
    assert a.offset == b.offset and np.linalg.norm(a.offset) > 0.0
    assert off.offset == (0.0, 0.0, 0.0) and not off.enabled
    with pytest.raises(ValueError, match="sigma"):
        EstimateDrift(-1.0)


def test_position_setpoints_are_flown_on_the_estimate_velocities_are_not():
    offset = (0.5, -1.0, 0.2)
    held = flown_on_estimate(Command(math.nan, math.nan, math.nan, position_ned_m=(10.0, 0.0, -5.0)), offset)
    assert held.position_ned_m == pytest.approx((9.5, 1.0, -5.2))
    velocity = Command(1.0, 0.0, 0.0)
    assert flown_on_estimate(velocity, offset) is velocity
