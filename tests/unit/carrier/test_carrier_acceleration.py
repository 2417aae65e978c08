"""The carrier's measured acceleration (mission.carrier.acceleration): numbers, repeated samples,
reset, and the controller publishing it only when configured."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mission.carrier.acceleration import AccelerationEstimate


def test_a_constant_acceleration_is_measured_exactly_and_repeats_of_a_sample_change_nothing() -> None:
    est = AccelerationEstimate(0.1)
    assert est.update(0.0, np.zeros(3)) is None  # one sample: no difference yet
    for k in range(1, 30):
        t = k / 29.0  # PX4 streams LOCAL_POSITION_NED at ~29 Hz
        a = est.update(t, np.array([1.5 * t, -0.5 * t, 0.0]))
        again = est.update(t, np.array([99.0, 99.0, 99.0]))  # the same own state seen on the next tick
        assert again is a
    np.testing.assert_allclose(est.value, [1.5, -0.5, 0.0], atol=1e-9)


def test_a_velocity_step_is_low_passed_with_the_time_constant() -> None:
    """A leap of 1 m/s within one 0.05 s sample reads 20 m/s^2 raw; with tau = 0.1 s the estimate
    then decays as exp(-t / tau)."""
    est = AccelerationEstimate(0.1)
    est.update(0.0, np.zeros(3))
    est.update(0.05, np.zeros(3))
    est.update(0.10, np.array([1.0, 0.0, 0.0]))
    first = float(est.value[0])
    assert first == pytest.approx(20.0 * (1.0 - math.exp(-0.5)), rel=1e-9)
    est.update(0.20, np.array([1.0, 0.0, 0.0]))
    assert float(est.value[0]) == pytest.approx(first * math.exp(-1.0), rel=1e-9)


def test_reset_forgets_so_a_gap_is_not_differenced_and_tau_must_be_positive() -> None:
    est = AccelerationEstimate(0.1)
    est.update(0.0, np.zeros(3))
    est.update(0.1, np.array([0.1, 0.0, 0.0]))
    est.reset()
    assert est.value is None
    assert est.update(5.0, np.array([3.0, 0.0, 0.0])) is None  # 3 m/s after a stale gap: no 0.6 m/s^2 made up
    with pytest.raises(ValueError):
        AccelerationEstimate(0.0)
