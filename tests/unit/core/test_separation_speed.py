"""The carrier's approach arrives at the separation slowly (``carrier.separation_speed_m_s``)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mission.carrier.step import carrier_model
from mission.config.schema import load_config
from mission.core.law import norm
from mission.core.tick import SeparationSpeed, carrier_tick
from sim.batch.closed_loop import simulate
from tests.conftest import CONFIGS


@pytest.fixture(scope="module")
def relnav():
    return load_config(CONFIGS / "px4_sitl_relnav.toml")


def _at(model, distance_m: float) -> np.ndarray:
    """The carrier on the ground, ``distance_m`` [m] from the target as the law measures it (3D)."""
    target = np.asarray(model.target, dtype=float)
    horizontal = float(np.sqrt(distance_m ** 2 - target[2] ** 2))
    return np.array([target[0] - horizontal, target[1], 0.0])


def test_off_unless_set(relnav):
    assert carrier_model(load_config(CONFIGS / "px4_sitl_cycle.toml")).separation_speed is None
    assert carrier_model(relnav).separation_speed == SeparationSpeed(0.8, 0.2, 8.0 + 3.0)


@pytest.mark.parametrize("distance_m, speed_m_s", [(40.0, 1.2), (11.0 + 2.0, np.sqrt(0.64 + 0.8)),
                                                   (11.0, 0.8), (9.0, 0.8), (8.2, 0.8)])
def test_the_speed_falls_to_the_separation_speed_from_bc_plus_the_room(relnav, distance_m, speed_m_s):
    model = carrier_model(relnav)  # the law asks k_c |e_tc| >= 4 m/s here: only the limits bind
    u = carrier_tick(_at(model, distance_m), False, model).u
    assert float(norm(u)) == pytest.approx(speed_m_s, abs=1e-9)
    assert u[2] == 0.0 and float(u[0]) > 0  # in the plane, still towards the target


def test_the_cap_never_rises_as_it_closes_in_and_a_separated_carrier_is_not_pushed(relnav):
    model = carrier_model(relnav)
    speeds = [float(norm(carrier_tick(_at(model, d), False, model).u)) for d in np.linspace(20.0, 8.0, 121)]
    assert all(b <= a + 1e-12 for a, b in zip(speeds, speeds[1:]))
    assert min(speeds) == pytest.approx(0.8) and max(speeds) == pytest.approx(1.2)
    assert not np.any(carrier_tick(_at(model, 9.0), True, model).u)


def test_a_batch_gets_each_rows_cap(relnav):
    model = carrier_model(relnav)
    rows = np.array([_at(model, d) for d in (30.0, 12.0, 9.0)])
    batch = dataclasses.replace(model, target=np.broadcast_to(model.target, rows.shape).copy())
    u = carrier_tick(rows, np.array([False, False, True]), batch).u
    np.testing.assert_allclose(norm(u), [1.2, float(np.sqrt(0.64 + 0.4)), 0.0], atol=1e-9)


def test_a_carrier_that_stops_at_the_separation_stops_farther_from_the_target(relnav):
    """The paper's loop (its carrier stops at the separation, braking at the carrier's 1 m/s^2):
    it drives in at 1.2 m/s and separates at 0.8 m/s, and stands 0.4 m farther out."""
    model = dataclasses.replace(carrier_model(relnav), target=np.array([15.0, 0.0, 0.0]))
    start = np.array([-25.0, 0.0, 0.0])
    fast = simulate(dataclasses.replace(model, separation_speed=None), start, duration_s=40.0, dt_s=0.02,
                    record_every=1)
    slow = simulate(model, start, duration_s=40.0, dt_s=0.02, record_every=1)
    speeds = []
    for r in (fast, slow):
        assert r.carrier_target_distance_at_separation_m[0] == pytest.approx(8.0, abs=0.01) and r.p3[0]
        speeds.append(float(norm(r.u_c[int(np.searchsorted(r.t, r.separation_time_s[0])) - 1, 0])))
    assert speeds == pytest.approx([1.2, 0.8], abs=0.01)
    assert fast.min_carrier_target_distance_m[0] == pytest.approx(8.0 - 1.2 ** 2 / 2, abs=0.05)
    assert slow.min_carrier_target_distance_m[0] == pytest.approx(8.0 - 0.8 ** 2 / 2, abs=0.05)
