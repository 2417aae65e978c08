"""A velocity made consistent with its position (mission.core.consistent_velocity): a biased
velocity is corrected to the position's rate with the time constant; an exact one is untouched."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mission.core.consistent_velocity import PositionConsistentVelocity


def test_a_velocity_that_says_less_than_the_position_moves_is_corrected_to_the_position_s_rate() -> None:
    """Position moving at 1.25 m/s north, velocity saying 1.0: the bias estimate approaches 0.25
    as 1 - exp(-t / tau) (first order), whatever the sample spacing."""
    fix = PositionConsistentVelocity(1.0)
    t, out = 0.0, None
    rng = np.random.default_rng(1)
    while t < 3.0:
        out = fix.update(t, np.array([1.25 * t, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]))
        t += float(rng.uniform(0.02, 0.05))  # PX4's ~29 Hz with jitter
    first = fix.update(t, np.array([1.25 * t, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]))
    assert fix.bias is not None and out is not None
    # the first difference comes after the first sample: the filter ran for t minus that sample
    assert float(first[0]) == pytest.approx(1.0 + 0.25 * (1.0 - math.exp(-t)), abs=1e-9)
    assert first[1] == first[2] == 0.0


def test_a_consistent_accelerating_state_gets_no_correction_and_repeats_change_nothing() -> None:
    fix = PositionConsistentVelocity(0.5)
    for k in range(60):
        t = k / 29.0
        v = fix.update(t, np.array([0.5 * t * t, 0.0, 0.0]), np.array([t, 0.0, 0.0]))  # 1 m/s^2
        assert float(v[0]) == pytest.approx(t, abs=1e-12)
        again = fix.update(t, np.array([9.0, 9.0, 9.0]), np.array([t, 0.0, 0.0]))  # the same state on the next tick
        assert float(again[0]) == pytest.approx(t, abs=1e-12)


def test_reset_forgets_the_last_sample_not_the_bias_and_tau_must_be_positive() -> None:
    fix = PositionConsistentVelocity(0.1)
    fix.update(0.0, np.zeros(3), np.zeros(3))
    fix.update(0.1, np.array([0.05, 0.0, 0.0]), np.zeros(3))
    bias = fix.bias.copy()
    fix.reset()
    v = fix.update(5.0, np.array([100.0, 0.0, 0.0]), np.zeros(3))  # a jump across the gap is not a rate
    np.testing.assert_array_equal(v, bias)
    with pytest.raises(ValueError):
        PositionConsistentVelocity(0.0)


def test_the_mission_observes_its_vehicle_s_velocity_made_consistent_with_its_position() -> None:
    """mission.velocity_bias_tau_s: the controller's vehicle observation carries the corrected
    velocity (an EKF that says 0.44 m/s east while its position moves 0.12 m/s west, as PX4's did
    on SIH), each LOCAL_POSITION_NED sample counted once."""
    from types import SimpleNamespace

    from mission.mavlink.telemetry import vehicle_report
    from mission.passenger.step import observe_vehicle

    def _vehicle_obs(state, fix=None):  # type: ignore[no-untyped-def]
        return observe_vehicle(vehicle_report(state), fix)

    fix = PositionConsistentVelocity(0.5)
    obs = None
    for k in range(150):  # 3 s at 50 Hz
        t = k * 0.02
        state = SimpleNamespace(heartbeat_rx_s=t, position_ned_m=[0.0, -0.12 * t, -1.5], velocity_ned_m_s=[0.0, 0.44, 0.0],
                                position_rx_s=t, t_s=t, position_t_s=t, position_valid=True, armed=True,
                                mode="OFFBOARD", heartbeat_age_s=0.0, system_status=4, battery_pct=None,
                                landed_state=2, believed_armed=True, believed_on_ground=False)
        obs = _vehicle_obs(state, fix)
        assert _vehicle_obs(state) is not None
    assert obs is not None
    assert float(obs.velocity_ned_m_s[1]) == pytest.approx(-0.12 + 0.56 * math.exp(-2.98 / 0.5), abs=1e-6)
    raw = _vehicle_obs(state)  # without the fix: the estimator's velocity as it came
    assert raw is not None and float(raw.velocity_ned_m_s[1]) == pytest.approx(0.44)


@pytest.mark.parametrize("yaw_deg", [0.0, 30.0, -120.0])
def test_the_part_across_the_heading_has_its_own_time_constant(yaw_deg: float) -> None:
    """A rover heading ``yaw`` whose position drifts 0.2 m/s along and 0.2 m/s across its heading
    while its velocity says neither: with tau 1.0 s and across_tau 0.3 s, after 0.6 s the bias's
    across part is 0.2 (1 - exp(-2)) and its along part 0.2 (1 - exp(-0.6)); without across_tau
    both are the latter, and without a heading the split is not made."""
    yaw = math.radians(yaw_deg)
    along, across = np.array([math.cos(yaw), math.sin(yaw), 0.0]), np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    drift = 0.2 * along + 0.2 * across
    split, plain, blind = (PositionConsistentVelocity(1.0, 0.3), PositionConsistentVelocity(1.0),
                           PositionConsistentVelocity(1.0, 0.3))
    for k in range(31):  # 0.6 s at 50 Hz
        t = 0.02 * k
        split.update(t, drift * t, np.zeros(3), yaw)
        plain.update(t, drift * t, np.zeros(3), yaw)
        blind.update(t, drift * t, np.zeros(3))
    assert split.bias is not None and plain.bias is not None and blind.bias is not None
    assert float(split.bias @ across) == pytest.approx(0.2 * (1.0 - math.exp(-2.0)), abs=1e-9)
    assert float(split.bias @ along) == pytest.approx(0.2 * (1.0 - math.exp(-0.6)), abs=1e-9)
    assert plain.bias == pytest.approx(0.2 * (1.0 - math.exp(-0.6)) * (along + across), abs=1e-9)
    assert blind.bias == pytest.approx(plain.bias, abs=1e-12)
