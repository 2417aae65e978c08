"""The simulated world's GNSS errors (sim/gnss.py, the mock's passenger bias): their statistics
are the configuration's, seeded, and off unless asked (docs/relnav.md)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mission.carrier.backends import OwnState
from mission.config.relnav import CarrierGnssSection, PassengerGnssSection
from mission.config.schema import from_dict
from mission.errors import ConfigError
from sim.gnss import CarrierGnss, ErringCarrier, GaussMarkovBias
from sim.vehicle.estimator import BiasedEstimateError, EstimateError
from sim.vehicle.mock import estimate_error_of
from sim.vehicle.options import VehicleOptions


def _autocorrelation(x: np.ndarray, lag: int) -> float:
    x = x - x.mean()
    return float((x[:-lag] * x[lag:]).mean() / (x * x).mean())


def _errors(cfg: CarrierGnssSection, duration_s: float) -> tuple[np.ndarray, list]:
    """The published position errors (n, 3) of a carrier standing still, and the fixes."""
    gnss = CarrierGnss(cfg)
    fixes = []
    for k in range(int(duration_s * cfg.rate_hz) + 20):
        fixes += gnss.observe(k / cfg.rate_hz, np.zeros(3), np.zeros(3))
    return np.array([f.error_ned_m for f in fixes]), fixes


def test_the_bias_has_the_configured_sigma_and_time_constant():
    """2 x 8000 samples at 1 Hz of a 1.5 m, 40 s bias (200 time constants): sigma within 15 %,
    autocorrelation at one time constant within 0.1 of 1/e (sampling spread: ~7 % and ~0.05)."""
    cfg = CarrierGnssSection(enabled=True, bias_sigma_m=1.5, bias_tau_s=40.0, position_sigma_m=0.0, rate_hz=1.0,
                             latency_s=0.0, jitter_s=0.0, seed=7)
    err, _ = _errors(cfg, 8_000.0)
    for axis in (0, 1):
        assert err[:, axis].std() == pytest.approx(1.5, rel=0.15)
        assert _autocorrelation(err[:, axis], 40) == pytest.approx(math.exp(-1.0), abs=0.1)
    assert err[:, 2].std() == pytest.approx(1.5 * cfg.vertical_factor, rel=0.15)


def test_white_noise_rate_latency_and_jitter():
    cfg = CarrierGnssSection(enabled=True, bias_sigma_m=0.0, position_sigma_m=0.3, velocity_sigma_m_s=0.2,
                             rate_hz=5.0, latency_s=0.2, jitter_s=0.1, seed=3)
    gnss = CarrierGnss(cfg)
    fixes = []
    for k in range(20_000):  # 200 s at 100 Hz, the truth moving at 1 m/s north
        t = k * 0.01
        fixes += gnss.observe(t, np.array([t, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]))
    err = np.array([f.error_ned_m for f in fixes])
    assert err[:, 0].std() == pytest.approx(0.3, rel=0.1)
    assert abs(_autocorrelation(err[:, 0], 1)) < 0.1  # white
    for f in fixes:  # the error is what it says: the truth at the fix's own time
        assert f.position_ned_m[0] - f.error_ned_m[0] == pytest.approx(f.t_s, abs=1e-9)
    vel = np.array([f.velocity_ned_m_s for f in fixes]) - [1.0, 0.0, 0.0]
    assert vel.std(axis=0) == pytest.approx([0.2, 0.2, 0.2], rel=0.1)
    assert np.diff([f.t_s for f in sorted(fixes, key=lambda f: f.t_s)]) == pytest.approx(0.2)
    delay = np.array([f.published_t_s - f.t_s for f in fixes])
    assert delay.min() >= 0.1 and delay.max() <= 0.3 and delay.mean() == pytest.approx(0.2, abs=0.01)
    assert len(fixes) == pytest.approx(5 * 200, abs=3)


def test_rtk_is_centimetres_with_float_fallbacks_at_decimetres():
    cfg = CarrierGnssSection(enabled=True, mode="rtk", rtk_fixed_mean_s=20.0, rtk_float_mean_s=5.0, rate_hz=2.0,
                             latency_s=0.0, jitter_s=0.0, seed=11)
    err, fixes = _errors(cfg, 2_500.0)
    floating = np.array([f.float_solution for f in fixes])
    assert floating.mean() == pytest.approx(5.0 / 25.0, abs=0.06)  # the time in float (~100 fallbacks)
    assert err[~floating, 0].std() == pytest.approx(0.02, rel=0.1)  # fixed: white centimetres, no bias
    assert 0.15 < err[floating, 0].std() < 0.45  # float: the 0.3 m wander, decimetres


def test_seeded_and_off_by_default():
    assert not CarrierGnssSection().enabled and PassengerGnssSection().bias_sigma_m == 0.0
    cfg = CarrierGnssSection(enabled=True, seed=5)
    a, _ = _errors(cfg, 10.0)
    b, _ = _errors(cfg, 10.0)
    c, _ = _errors(CarrierGnssSection(enabled=True, seed=6), 10.0)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert type(estimate_error_of(VehicleOptions())) is EstimateError


def test_the_configuration_rejects_a_fix_published_before_it_is_measured():
    with pytest.raises(ConfigError, match="jitter_s"):
        from_dict({"world": {"carrier_gnss": {"latency_s": 0.1, "jitter_s": 0.2}}})
    cfg = from_dict({"world": {"carrier_gnss": {"enabled": True, "mode": "rtk"}}})
    assert cfg.world.carrier_gnss.mode == "rtk"


class _Standing:
    """A carrier backend standing at (3, 4, 0) [m] on a clock the test moves."""

    name, brakes_itself = "still", False

    def __init__(self) -> None:
        self.t_s = 0.0

    def own_state(self) -> OwnState:
        return OwnState(self.t_s, np.array([3.0, 4.0, 0.0]), np.zeros(3), 0.5)


def test_an_erring_carrier_publishes_its_newest_fix():
    inner = _Standing()
    carrier = ErringCarrier(inner, CarrierGnssSection(enabled=True, rate_hz=10.0, latency_s=0.2, jitter_s=0.0, seed=2))
    assert carrier.own_state() is None  # nothing published yet
    inner.t_s = 0.25
    state = carrier.own_state()
    assert state is not None and state.t_s == pytest.approx(0.0)  # measured 0.2 s before
    assert state.inertial is not None and state.inertial.t_s == 0.25  # its own navigation state: now, exact
    assert state.inertial.yaw_rad == 0.5 and np.array_equal(state.inertial.position_ned_m, [3.0, 4.0, 0.0])
    assert state.yaw_rad is not None and 0.0 < abs(state.yaw_rad - 0.5) < 0.2  # its heading, 2 deg of noise
    quiet = ErringCarrier(inner, CarrierGnssSection(enabled=True, heading_sigma_deg=0.0, seed=2))
    assert quiet.own_state() is None
    inner.t_s = 0.5
    assert quiet.own_state().yaw_rad == 0.5  # no heading noise asked: its true heading
    assert carrier.truth is not None and np.array_equal(carrier.truth.position_ned_m, [3.0, 4.0, 0.0])
    assert 0.3 < np.linalg.norm(state.position_ned_m[:2] - [3.0, 4.0]) < 10.0  # the bias and the noise


def test_the_passengers_gnss_bias_is_smooth_seeded_and_of_its_statistics():
    """A 2 m, 10 s bias over 200 time constants: sigma within 20 %, autocorrelation at one time
    constant (1 + 1) / e for a second-order process, and smooth: its 0.5 s changes are about
    sigma dt / tau (a first-order process's would be six times larger)."""
    gnss = PassengerGnssSection(bias_sigma_m=2.0, bias_tau_s=10.0, seed=4)
    est = estimate_error_of(VehicleOptions(passenger_gnss=gnss, estimate_error=0.0))
    assert isinstance(est, BiasedEstimateError) and est.enabled
    start = est.position
    north = []
    for _ in range(4_000):  # 2000 s in steps of 0.5 s (the process is exact for any step)
        est.advance(0.5)
        north.append(est.position[0])
        assert est.position == est.gnss_bias  # no other error asked
    x = np.array(north)
    assert x.std() == pytest.approx(2.0, rel=0.2)
    assert _autocorrelation(x, 20) == pytest.approx(2.0 / math.e, abs=0.1)
    assert np.diff(x).std() < 1.5 * 2.0 * 0.5 / 10.0
    again = estimate_error_of(VehicleOptions(passenger_gnss=gnss, estimate_error=0.0))
    assert again.position == start
    assert GaussMarkovBias(1.0, 10.0, 1.0, np.random.default_rng(0)).advance(0.0).shape == (3,)


def test_mock_vehicle_takes_the_passengers_bias_from_a_configuration(tmp_path):
    from sim.vehicle.cli import passenger_gnss_of

    path = tmp_path / "world.toml"
    path.write_text("[world.passenger_gnss]\nbias_sigma_m = 1.0\nseed = 9\n")
    gnss = passenger_gnss_of(path)
    assert gnss is not None and gnss.bias_sigma_m == 1.0 and gnss.seed == 9
    path.write_text("[world.carrier_gnss]\nenabled = true\n")
    assert passenger_gnss_of(path) is None and passenger_gnss_of(None) is None
