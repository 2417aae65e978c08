"""The errors of PX4's estimate as the mock vehicle adds them (sim/vehicle/estimator.py), off by default."""
from __future__ import annotations

import math

import numpy as np
import pytest

from sim.vehicle.estimator import PX4_SITL, EstimateError


def _run(error: EstimateError, steps: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    v, p = [], []
    for _ in range(steps):
        error.advance(dt)
        v.append(error.velocity)
        p.append(error.position)
    return np.array(v), np.array(p)


def test_errors_have_the_fitted_spread_and_a_smooth_correlation():
    dt = 0.05
    v, p = _run(EstimateError(1.0, seed=3), 100_000, dt)  # 5000 s
    assert v[:, :2].std() == pytest.approx(PX4_SITL.sigma_v_m_s, rel=0.1)
    assert p[:, :2].std() == pytest.approx(PX4_SITL.sigma_p_m, rel=0.1)
    assert v[:, 2].std() == pytest.approx(PX4_SITL.sigma_v_m_s * PX4_SITL.vertical_v, rel=0.15)
    # second order: autocorrelation (1 + t/tau) exp(-t/tau), 2/e at one time constant
    lag = round(PX4_SITL.tau_v_s / dt)
    acf = np.mean([np.corrcoef(v[:-lag, i], v[lag:, i])[0, 1] for i in (0, 1)])
    assert acf == pytest.approx(2 * math.exp(-1.0), abs=0.08)
    # the velocity error is not the position error's rate: the estimate's velocity and position disagree
    rate = np.diff(p[:, 0]) / dt
    assert abs(np.corrcoef(rate, v[1:, 0])[0, 1]) < 0.1


def test_same_seed_same_errors_and_zero_scale_means_none():
    a, b, off = EstimateError(1.0, seed=7), EstimateError(1.0, seed=7), EstimateError(0.0, seed=7)
    for _ in range(1000):
        for e in (a, b, off):
            e.advance(0.005)
    assert a.velocity == b.velocity and a.position == b.position and np.linalg.norm(a.velocity) > 0.0
    assert off.velocity == off.position == (0.0, 0.0, 0.0) and not off.enabled
    with pytest.raises(ValueError, match="scale"):
        EstimateError(-1.0)
