"""The mock's dynamics against a real PX4 SITL's recorded offboard responses.

The recorded setpoint sequence (tests/data/px4_responses/, from ../shared/px4_sitl/responses/) is
replayed into the dynamics on PX4's own clock and compared segment by segment. ``original`` is the
recording the airframe constants were fitted to; ``repeat`` is the same sequence flown again on a
fresh PX4 and was not used by the fit. Targets: mean RMS velocity difference <= 0.15
m/s over the step, ramp and sine segments (the two PX4 recordings differ from each other by 0.137);
ramp lag within 25 % of PX4's. ``python -m bench.px4_response_fit`` prints the table.
"""
from __future__ import annotations


import numpy as np
import pytest

from sim.sitl.replay import Comparison, RecordedEstimateError, compare, load_recording, px4_vs_px4_rms, ramp_lag_m
from sim.vehicle.physics.multicopter import Airframe, Limits
from tests.conftest import ROOT

DATA = ROOT / "tests" / "data" / "px4_responses"


@pytest.fixture(scope="module")
def recordings():
    return {name: load_recording(DATA / f"{name}.csv.gz") for name in ("original", "repeat")}


@pytest.fixture(scope="module")
def comparisons(recordings) -> dict[str, Comparison]:
    return {name: compare(rec, Limits()) for name, rec in recordings.items()}


@pytest.mark.parametrize("name", ["original", "repeat"])
def test_mean_rms_velocity_difference_within_target(comparisons, name):
    c = comparisons[name]
    assert set(c.rms_m_s) == {"step_north_2", "step_east_2", "step_diag_4p2", "step_up_1", "step_down_1",
                              "ramp_velocity_only", "ramp_pos_vel_acc", "sine_north_1m_s_0.25hz",
                              "sine_north_1m_s_0.5hz", "sine_north_1m_s_1.0hz"}
    assert c.mean_rms_m_s <= 0.15  # measured 0.134 (original), 0.119 (repeat)
    # no segment far off: the worst is the full-setpoint ramp, where PX4's own position estimate
    # drifts by decimetres (the two recordings differ by 0.33 there)
    assert max(c.rms_m_s.values()) <= 0.40
    assert sorted(c.rms_m_s.values())[-2] <= 0.17


def test_the_old_first_order_mock_misses_the_target(recordings):
    """The test can fail: a fast first-order response without drag (the mock's first model:
    90 % in 0.67 s, no deficit) is far from PX4."""
    stiff = Limits(airframe=Airframe(drag_1_s=0.0, tilt_tau_s=0.05, thrust_tau_s=0.05, drag_z_1_s=0.0))
    assert compare(recordings["original"], stiff).mean_rms_m_s > 0.25


def test_velocity_only_ramp_lag_within_25_percent_of_px4(recordings, comparisons):
    """The carrier-like ramp as velocity setpoints: PX4 falls metres behind the commanded path.
    Compared on PX4's velocity (its position estimate wanders by 1-2 m in that segment)."""
    for name, rec in recordings.items():
        px4_lag = ramp_lag_m(rec, "ramp_velocity_only", rec.vel)  # 3.81 / 3.76 m
        assert px4_lag > 3.0
        assert comparisons[name].lag_mock_m["ramp_velocity_only"] == pytest.approx(px4_lag, rel=0.25)


def test_full_setpoint_ramp_lag_within_25_percent_of_px4(recordings, comparisons):
    """The same ramp as position + velocity + acceleration (type_mask 3072): PX4 follows within
    decimetres. Its two recordings differ by 70 % (0.44 and 0.75 m: its position estimate drifts
    by 0.7-2 m in that segment), so no single value is within 25 % of both; the mock's lag
    (0.74 / 0.79 m) is within 25 % of the repeat's and an order of magnitude below the
    velocity-only ramp's, as on PX4 (``python -m bench.px4_response_fit`` prints every ratio)."""
    px4 = {name: ramp_lag_m(rec, "ramp_pos_vel_acc") for name, rec in recordings.items()}
    for name, c in comparisons.items():
        mock = c.lag_mock_m["ramp_pos_vel_acc"]
        assert any(mock == pytest.approx(lag, rel=0.25) for lag in px4.values()), (mock, px4)
        assert mock < 0.3 * c.lag_mock_m["ramp_velocity_only"]


def test_px4_differs_from_itself_by_about_the_target(recordings):
    rms = px4_vs_px4_rms(recordings["original"], recordings["repeat"])
    assert float(np.mean(list(rms.values()))) == pytest.approx(0.137, abs=0.01)


@pytest.fixture(scope="module")
def unseen():
    """Another sequence, flown on a fresh PX4 with SIH's true velocity recorded beside its estimate
    (``bench/px4_response_record.py``): neither the airframe fit nor the error model saw it."""
    return load_recording(DATA / "unseen.csv.gz")


def test_the_exact_mock_meets_the_target_on_an_unseen_sequence(unseen):
    c = compare(unseen, Limits())
    assert c.mean_rms_m_s <= 0.15  # measured 0.113 (0.071-0.205 per segment)
    assert max(c.rms_m_s.values()) <= 0.25  # the full-setpoint ramp east, 0.205: PX4's estimate error (below)


def test_px4s_own_velocity_error_fed_into_the_mock_brings_it_closer(unseen):
    """PX4's controller flies its estimate: the mock fed with PX4's velocity error as measured in
    that flight (estimate - SIH's truth) answers closer to PX4 than with an exact estimate, most in
    the segments that hold a position (the full-setpoint ramp 0.205 -> 0.106 m/s)."""
    exact = compare(unseen, Limits())
    fed = compare(unseen, Limits(), estimate=RecordedEstimateError(unseen))
    assert fed.mean_rms_m_s < exact.mean_rms_m_s - 0.01  # measured 0.099 against 0.113
    assert fed.rms_m_s["ramp_east_pos_vel_acc"] < 0.6 * exact.rms_m_s["ramp_east_pos_vel_acc"]
