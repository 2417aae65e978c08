"""The carrier's measured acceleration (mission.carrier.acceleration): numbers, repeated samples,
reset, the controller publishing it only when configured, and a carrier publishing GNSS fixes
measuring it from its inertial velocity."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mission.carrier.acceleration import AccelerationEstimate, inertial_sample
from mission.carrier.backends import OwnState
from mission.config.relnav import CarrierGnssSection
from sim.gnss import ErringCarrier


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


class _Accelerating:
    """A carrier backend pulling away north at 1 m/s^2 from t = 1 s on a clock the test moves,
    heading north."""

    name, brakes_itself = "accelerating", False

    def __init__(self) -> None:
        self.t_s = 0.0

    def own_state(self) -> OwnState:
        moving = max(self.t_s - 1.0, 0.0)
        return OwnState(self.t_s, np.array([0.5 * moving ** 2, 0.0, 0.0]), np.array([moving, 0.0, 0.0]), 0.0)


def _measured(from_inertial: bool, seed: int) -> tuple[list[float], list[float]]:
    """The acceleration north [m/s^2] measured at 30 Hz over 4 s of a carrier publishing its GNSS
    fixes (10 Hz, 0.2 s late, 0.2 m/s of velocity noise), and the times [s] it was measured for:
    from its inertial velocity (``inertial_sample``) or from the fixes' velocity."""
    robot = _Accelerating()
    carrier = ErringCarrier(robot, CarrierGnssSection(enabled=True, rate_hz=10.0, latency_s=0.2, jitter_s=0.0,
                                                      velocity_sigma_m_s=0.2, seed=seed))
    est = AccelerationEstimate(0.1)
    out, times = [], []
    for k in range(1, 121):
        robot.t_s = k / 30.0
        state = carrier.own_state()
        if state is None:
            continue
        t, v = inertial_sample(state, state.velocity_ned_m_s, 3, True) if from_inertial else (state.t_s, state.velocity_ned_m_s)
        a = est.update(t, v)
        if a is not None:
            out.append(float(a[0]))
            times.append(robot.t_s)
    return out, times


def test_a_carrier_publishing_gnss_fixes_measures_its_acceleration_from_its_inertial_velocity() -> None:
    """The pull-away at 1 m/s^2 (from 1 s): from the robot's inertial velocity the acceleration
    reads 1 within 0.05 from 1.5 s, and under 0.05 before the pull-away; differentiated from the
    fixes (10 Hz, 0.2 m/s of noise, 0.2 s late) it swings by metres per second squared."""
    inertial, times = _measured(True, seed=3)
    settled = [a for a, t in zip(inertial, times) if t >= 1.5]
    before = [a for a, t in zip(inertial, times) if t < 1.0]
    assert settled and max(abs(a - 1.0) for a in settled) < 0.05
    assert before and max(abs(a) for a in before) < 0.05
    fixes, _ = _measured(False, seed=3)
    assert max(abs(a - 1.0) for a in fixes[-60:]) > 1.0  # what the fixes gave: noise, not the pull-away


def test_a_state_with_no_inertial_velocity_is_measured_from_what_is_published() -> None:
    state = OwnState(2.0, np.zeros(3), np.array([1.0, 1.0, 0.0]), math.pi / 2)
    t, v = inertial_sample(state, np.array([1.0, 0.0, 0.0]), 3, True)
    assert t == 2.0 and np.array_equal(v, [1.0, 0.0, 0.0])  # as published: its caller has taken it along its heading
    gnss = OwnState(2.0, np.zeros(3), np.zeros(3), 0.0,  # its published heading's noise is not used
                    inertial=OwnState(2.2, np.zeros(3), np.array([0.3, 1.0, 0.0]), math.pi / 2))
    t, v = inertial_sample(gnss, np.zeros(3), 3, True)
    assert t == 2.2
    np.testing.assert_allclose(v, [0.0, 1.0, 0.0], atol=1e-12)  # along its heading (east): the sideways 0.3 gone
    t, v = inertial_sample(gnss, np.zeros(3), 2, False)
    np.testing.assert_allclose(v, [0.3, 1.0, 0.0])  # a holonomic carrier's, in the plane
