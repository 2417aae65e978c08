"""The riding passenger's acceleration limit (``safety.riding_max_accel_m_s2``): riding, the
passenger must follow what its carrier does, and a rover breaking free from a stand leaps faster
than the passenger's own limit (docs/relnav.md, "Riding a rover that leaps"); the separation and
everything after keep ``safety.passenger_max_accel_m_s2``."""
from __future__ import annotations

import pytest

from mission.config.schema import load_config
from mission.controller import mission_model
from mission.core.law import norm
from mission.errors import ConfigError
from mission.phases import Phase
from tests.conftest import CONFIGS
from tests.unit.phases.test_phases import fly


def _config(riding_accel: float | None, own: float | None = 2.0):
    """demo.toml's mission by velocity setpoints (the world of test_phases' ``fly`` integrates the
    setpoint as a velocity), the passenger's own limit ``own``, riding at ``riding_accel``."""
    cfg = load_config(CONFIGS / "demo.toml")
    mission = cfg.mission.model_copy(update={"setpoint": "velocity", "track_gain": 1.5, "position_lead": 0.0,
                                             "drag_ff_per_s": 0.0, "integral_gain": 0.0})
    safety = type(cfg.safety).model_validate({**cfg.safety.model_dump(), "passenger_max_accel_m_s2": own,
                                              "riding_max_accel_m_s2": riding_accel})
    return cfg.model_copy(update={"mission": mission, "safety": safety})


def _ride(riding_accel: float | None) -> dict[str, float]:
    """test_phases' world: the carrier leaps from rest to 2 m/s in one tick as the ride starts, and
    the vehicle follows its setpoint through a 0.15 s lag. The largest offset from the dock point
    while riding [m], the largest step of the command between riding ticks [m/s], and the
    command's step at the separation tick against that tick's limit [m/s]."""
    model = mission_model(_config(riding_accel))
    where = {}

    def watch(k, obs):
        where[k] = obs.vehicle.position_ned_m.copy()

    _, log, _, _ = fly(model, vehicle_tau=0.15, on_tick=watch)
    riding = [k for k, (_, p, _) in enumerate(log) if p == Phase.RIDING]
    sent = [log[k][2].setpoint.velocity_ned_m_s for k in riding]
    i = next(k for k, (_, p, _) in enumerate(log) if p == Phase.SEPARATED)
    return {"offset": max(float(norm(log[k][2].dock - where[k])) for k in riding),
            "ride_step": max(float(norm(b - a)) for a, b in zip(sent, sent[1:])),
            "separation_step": float(norm(log[i][2].setpoint.velocity_ned_m_s - log[i - 1][2].setpoint.velocity_ned_m_s)),
            "separation_limit": model.command_safety.max_accel_m_s2 * model.dt_s}


def test_riding_follows_a_leaping_carrier_at_its_own_limit_and_separates_at_the_passengers():
    """At 2 m/s^2 (the passenger's own limit) the rider falls 0.92 m behind a carrier that leaps to
    2 m/s; at 4 m/s^2, 0.56 m, its command stepping at most 1.5 times the riding limit a tick;
    the separation's step stays within the passenger's own limit."""
    own, fast = _ride(None), _ride(4.0)
    assert fast["offset"] < 0.65 * own["offset"], (fast, own)
    assert own["ride_step"] <= 2.0 * 1.5 * 0.02 + 1e-9 < fast["ride_step"] <= 4.0 * 1.5 * 0.02 + 1e-9, (own, fast)
    for r in (own, fast):
        assert r["separation_step"] <= r["separation_limit"] + 1e-9, r


@pytest.mark.parametrize("riding, own", [(1.5, 2.0), (4.0, None)])
def test_a_riding_limit_below_the_passengers_own_or_without_it_is_refused(riding, own):
    with pytest.raises(ConfigError) as e:
        _config(riding, own)
    assert e.value.field == "safety.riding_max_accel_m_s2"
