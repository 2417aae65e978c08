"""The closed loop reproduces the paper: P1-P3, smooth departure, clearances, limits."""
from __future__ import annotations

import json

import numpy as np
import pytest

from mission.config.schema import from_dict, load_config
from mission.core.law import LawParams, norm
from mission.core.safety import Obstacles, SafetyConfig
from mission.core.tick import TickModel
from sim.batch.closed_loop import model_from_config, random_scenarios, simulate, simulate_config
from tests.conftest import CONFIGS


@pytest.fixture(scope="module")
def paper3d():
    cfg = load_config(CONFIGS / "paper_3d.toml")
    return cfg, simulate_config(cfg)


@pytest.fixture(scope="module")
def paper2d():
    cfg = load_config(CONFIGS / "paper_2d_obstacles.toml")
    return cfg, simulate_config(cfg)


def test_paper_3d_separates_at_2_4_s_with_e_tc_8(paper3d):
    cfg, r = paper3d
    s = r.summary()
    assert s["separation_time_s"] == pytest.approx(2.4, abs=0.05)
    assert s["carrier_target_distance_at_separation_m"] == pytest.approx(8.0, abs=0.05)
    d = r.distances()
    after = r.t > s["separation_time_s"] + 0.01
    np.testing.assert_allclose(d["e_tc"][after], 8.0, atol=0.05)  # the carrier stays put (P3)
    assert s["p1"] and s["p2"] and s["p3"]


def test_paper_3d_passenger_on_carrier_bit_for_bit_until_separation(paper3d):
    _, r = paper3d
    before = r.t < r.separation_time_s[0]
    assert np.all(r.x_p[before, 0] == r.x_c[before, 0])


def test_relative_input_continuous_at_separation(paper3d):
    _, r = paper3d
    # relative input just before separation is 0 (equilibrium i); just after, the cubic's value
    # at |e_tc| = b c - 1 mm: about 8 mm/s. A jump of the size of the carrier speed (~3 m/s)
    # would be the event-based behaviour the paper avoids.
    assert r.relative_input_jump_m_s[0] < 0.02
    assert r.relative_speed_at_separation_m_s[0] < 0.02


def test_unsaturated_law_is_violent_as_measured(paper3d):
    _, r = paper3d  # law fact 1 (docs/how-it-works.md): above 300 m/s in the 3D run
    assert r.max_passenger_speed_m_s[0] > 300


def test_decay_after_separation_is_algebraic(paper3d):
    _, r = paper3d  # law fact 4: ~1/t, so doubling time roughly halves the distance
    d = r.distances()["e_pt"]
    at = lambda t: d[np.argmin(abs(r.t - t))]  # noqa: E731
    ratio = at(5.0) / at(10.0)
    assert 1.5 < ratio < 4.0


def test_exactly_docked_on_axis_departs_within_1_s():
    p = LawParams()
    model = TickModel(law=p, target=np.array([30.0, 0.0]), obstacles=Obstacles.none(2),
                      passenger_safety=SafetyConfig(), carrier_safety=SafetyConfig(), planar_carrier=False)
    r = simulate(model, np.zeros(2), duration_s=6.0, dt_s=1e-3)
    assert r.p1[0]
    assert r.departure_delay_s[0] < 1.0
    assert r.x_p[-1, 0, 1] == 0.0  # on axis stays on axis


def test_departure_survives_where_absolute_coordinates_would_lose_it():
    # law fact 2: 1000 km from the origin, with a 1 nm departure margin, the passenger's
    # first increments are below one ULP of its absolute position; error coordinates keep them.
    far = np.array([1e6, 0.0])
    model = TickModel(law=LawParams(), target=far + [30.0, 0.0], obstacles=Obstacles.none(2),
                      passenger_safety=SafetyConfig(), carrier_safety=SafetyConfig(), planar_carrier=False,
                      departure_margin_m=1e-9)
    r = simulate(model, far, duration_s=5.0, dt_s=1e-3)
    first_increment = r.relative_speed_at_separation_m_s[0] * 1e-3
    assert far[0] + first_increment == far[0]  # lost in absolute coordinates
    assert r.p1[0] and r.departure_delay_s[0] < 1.0  # not lost here


def test_carrier_never_closer_than_b_c(paper3d):
    cfg, r = paper3d
    bc = cfg.law.params().separation_distance_m
    assert r.min_carrier_target_distance_m[0] >= bc - cfg.law.departure_margin_m - 1e-9


def test_2d_obstacles_keep_clearance_and_reach_target(paper2d):
    cfg, r = paper2d
    s = r.summary()
    assert s["min_obstacle_clearance_m"] >= 0.0
    assert s["p1"] and s["p2"] and s["p3"]
    assert r.separated[-1, 0]
    # Remark 1: the carrier keeps moving after separation
    assert norm(r.x_c[-1, 0] - r.x_c[np.searchsorted(r.t, s["separation_time_s"]) + 1, 0]) > 5.0


def test_2d_limits_are_never_exceeded(paper2d):
    cfg, r = paper2d
    assert r.max_passenger_speed_m_s[0] <= cfg.safety.passenger_max_speed_m_s + 1e-9
    carrier_speed = norm(r.u_c[:, 0])
    assert carrier_speed.max() <= cfg.safety.carrier_max_speed_m_s + 1e-9


def test_accel_limit_never_exceeded_without_obstacles():
    cfg = from_dict({"scenario": {"dim": 3, "carrier_start": [0, 0, 0], "target": [30, 5, -3]},
                     "safety": {"passenger_max_speed_m_s": 5.0, "passenger_max_accel_m_s2": 3.0, "carrier_max_speed_m_s": 2.0,
                                "carrier_max_accel_m_s2": 1.0},
                     "sim": {"dt_s": 0.005, "duration_s": 30.0}})
    r = simulate_config(cfg)
    assert r.max_passenger_accel_m_s2[0] <= 3.0 + 1e-6
    assert r.max_passenger_speed_m_s[0] <= 5.0 + 1e-9
    assert r.p1[0] and r.p2[0] and r.p3[0]


def test_random_scenarios_all_satisfy_p1_p3():
    cfg = load_config(CONFIGS / "paper_3d.toml")
    starts, targets = random_scenarios(cfg, 64, seed=7)
    r = simulate(model_from_config(cfg, target=targets), starts, duration_s=10.0, dt_s=1e-3, record_every=100)
    assert r.p1.all() and r.p2.all() and r.p3.all()
    np.testing.assert_allclose(r.carrier_target_distance_at_separation_m, 7.999, atol=1e-6)
    assert np.nanmax(r.relative_input_jump_m_s) < 0.02


def test_offset_start_breaks_p1():
    # A passenger that does not start on the carrier violates Assumption 2 and P1 must say so.
    cfg = load_config(CONFIGS / "paper_3d.toml")
    r = simulate(model_from_config(cfg), np.array(cfg.scenario.carrier_start), duration_s=5.0, dt_s=1e-3,
                 passenger_offset=np.array([0.3, 0.0, 0.0]))
    assert not r.p1[0]


def test_summary_is_json_with_documented_keys(paper3d):
    _, r = paper3d
    s = json.loads(json.dumps(r.summary()))
    for key in ("separation_time_s", "carrier_target_distance_at_separation_m", "relative_speed_at_separation_m_s",
                "relative_input_jump_m_s", "final_passenger_target_distance_m", "min_carrier_target_distance_m",
                "min_obstacle_clearance_m", "max_passenger_speed_m_s", "p1", "p2", "p3"):
        assert key in s
    assert s["min_obstacle_clearance_m"] is None
