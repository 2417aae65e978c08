"""``mission.near_deck_velocity_bias_tau_s``: over the deck (mission.phases.phase.NEAR_DECK: the
ride, the recovery's last phases) the vehicle's velocity made consistent with its position follows
the position's rate with a time constant of its own; elsewhere (flying to the target, returning)
``velocity_bias_tau_s``'s; the bias carries on across a switch."""
from __future__ import annotations

import numpy as np
import pytest

from mission.config.schema import load_config, with_overrides
from mission.errors import ConfigError
from mission.model import mission_model
from mission.passenger.inputs import PassengerInputs, VehicleReport
from mission.passenger.step import PassengerStep
from mission.phases import Phase
from tests.conftest import CONFIGS

VELOCITY_E = 0.44  # [m/s] east, what the estimator says
RATE_E = 0.24  # [m/s] east, what its position does: a bias (the velocity less the rate) of 0.2 m/s


def _report(t: float) -> VehicleReport:
    return VehicleReport(t_s=t, position_ned_m=np.array([0.0, RATE_E * t, -1.5]), velocity_ned_m_s=np.array([0.0, VELOCITY_E, 0.0]),
                         sample_t_s=t, rx_s=t, armed=True, mode="OFFBOARD", heartbeat_age_s=0.0, valid=True)


def _bias_after(step: PassengerStep, phase: Phase, start_s: float, seconds: float) -> float:
    """The east bias [m/s] after ``seconds`` of 50 Hz ticks in ``phase``, from ``start_s`` [s]."""
    obs = None
    for k in range(round(seconds / 0.02)):
        t = start_s + k * 0.02
        obs = step.observe(PassengerInputs(t, _report(t), None), phase)
    assert obs is not None and obs.vehicle is not None and obs.vehicle.velocity_bias_ned_m_s is not None
    return float(obs.vehicle.velocity_bias_ned_m_s[1])


def test_near_the_deck_the_bias_is_followed_with_its_own_time_constant() -> None:
    cfg = with_overrides(load_config(CONFIGS / "relnav.toml"), {"mission.near_deck_velocity_bias_tau_s": 0.1})
    assert cfg.mission.velocity_bias_tau_s == 0.5
    model = mission_model(cfg)
    away = PassengerStep(model, cfg.mission.velocity_bias_tau_s, cfg.mission.near_deck_velocity_bias_tau_s)
    near = PassengerStep(model, cfg.mission.velocity_bias_tau_s, cfg.mission.near_deck_velocity_bias_tau_s)
    # 0.2 s after the bias appears: 1 - exp(-0.2 / tau) of it (one tick less: the first sample has no rate)
    assert _bias_after(away, Phase.RETURNING, 0.0, 0.22) == pytest.approx(0.2 * (1 - np.exp(-0.2 / 0.5)), abs=0.005)
    assert _bias_after(near, Phase.RIDING, 0.0, 0.22) == pytest.approx(0.2 * (1 - np.exp(-0.2 / 0.1)), abs=0.005)
    # the bias carries on across the switch: the first tick in HOLDOFF moves it by one tick's gain, no more
    before = _bias_after(away, Phase.RETURNING, 0.22, 0.02)
    after = _bias_after(away, Phase.HOLDOFF, 0.24, 0.02)
    assert after - before == pytest.approx((0.2 - before) * (1 - np.exp(-0.02 / 0.1)), abs=1e-6)
    # unset: the same filter everywhere
    plain = PassengerStep(model, 0.5)
    assert _bias_after(plain, Phase.APPROACH, 0.0, 0.22) == pytest.approx(0.2 * (1 - np.exp(-0.2 / 0.5)), abs=0.005)


def test_a_near_deck_time_constant_without_the_filter_is_refused_naming_the_field() -> None:
    with pytest.raises(ConfigError, match="mission.near_deck_velocity_bias_tau_s"):
        with_overrides(load_config(CONFIGS / "demo.toml"), {"mission.velocity_bias_tau_s": 0.0,
                                                            "mission.near_deck_velocity_bias_tau_s": 0.1})
