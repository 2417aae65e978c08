"""The simulated world's downward rangefinder (sim/batch/rangefinder.py): the deck's top under the
vehicle when it is over the deck, else the ground; delivered after its latency; seeded."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from mission.config.schema import load_config, with_overrides
from mission.phases.measurements import DownwardRange
from sim.batch.rangefinder import WorldRangefinder
from tests.conftest import CONFIGS


def _world(vehicle_ned_m: np.ndarray, **overrides: object) -> SimpleNamespace:
    cfg = with_overrides(load_config(CONFIGS / "relnav.toml"), {"scenario.carrier_start": [0.0, 0.0, 0.0],
                                                                 "world.rangefinder.dropout_fraction": 0.0,
                                                                 **overrides})
    carrier_at = np.array([3.0, -2.0, -0.8])  # a deck 0.8 m over the ground
    return SimpleNamespace(cfg=cfg, vehicle=SimpleNamespace(true_position=vehicle_ned_m),
                           carrier=SimpleNamespace(true_at=lambda t: (carrier_at.copy(), np.zeros(3))),
                           scenario=SimpleNamespace(seed=0))


def _ranges(world: SimpleNamespace, until_s: float = 1.0) -> list[DownwardRange]:
    sensor = WorldRangefinder(world)  # type: ignore[arg-type]
    out: list[DownwardRange] = []
    for k in range(int(until_s / 0.02) + 1):
        out.extend(m for m in sensor.poll(k * 0.02) if isinstance(m, DownwardRange))
    return out


def test_over_the_deck_it_measures_the_deck_beside_it_the_ground():
    """configs/relnav.toml's hover ride: the deck's top at the carrier's reference point (the
    seat), radius 0.5 m; 2 m over the deck the range is 1.2 m (over a deck 0.8 m high), 2 m beside it 2 m."""
    over = _ranges(_world(np.array([3.2, -2.0, -2.0])))
    beside = _ranges(_world(np.array([5.0, -2.0, -2.0])))
    assert len(over) >= 20 and abs(float(np.mean([m.range_m for m in over])) - 1.2) < 0.03
    assert abs(float(np.mean([m.range_m for m in beside])) - 2.0) < 0.03
    assert all(m.sigma_m == 0.03 for m in over)


def test_latency_rate_range_and_dropouts():
    """25 Hz, each delivered ``latency_s`` after capture; none beyond ``max_range_m``; half lost
    at a dropout fraction of 0.5."""
    world = _world(np.array([3.0, -2.0, -2.0]), **{"world.rangefinder.latency_s": 0.1})
    sensor = WorldRangefinder(world)  # type: ignore[arg-type]
    for k in range(51):
        t = k * 0.02
        assert all(t - m.capture_t_s >= 0.1 - 1e-9 for m in sensor.poll(t))
    assert sensor.captured == 26  # every 0.04 s over 1 s
    assert _ranges(_world(np.array([3.0, -2.0, -12.0]))) == []
    lossy = _ranges(_world(np.array([3.0, -2.0, -2.0]), **{"world.rangefinder.dropout_fraction": 0.5}), 4.0)
    assert 30 <= len(lossy) <= 70
