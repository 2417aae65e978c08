"""`simulate` models what `run` flies for a mission config; Monte-Carlo scenarios and reports."""
from __future__ import annotations

import numpy as np
import pytest

from mission.config.schema import load_config, with_overrides
from mission.errors import ConfigError
from sim.batch.closed_loop import is_mission_config, random_scenarios, simulate_config, target_reachable
from sim.batch.simulate import format_case, run_monte_carlo
from tests.conftest import CONFIGS


def test_a_mission_config_is_simulated_as_flown_and_holds_p1_p3():
    cfg = with_overrides(load_config(CONFIGS / "demo.toml"), {"sim.dt_s": 0.002})
    assert is_mission_config(load_config(CONFIGS / "demo.toml")) and not is_mission_config(load_config(CONFIGS / "paper_3d.toml"))
    flown = simulate_config(cfg).summary()
    assert flown["p1"] and flown["p2"] and flown["p3"]
    # separation measured from the dock point, at the time the demo flight separates (12.4 s)
    assert flown["carrier_target_distance_at_separation_m"] == pytest.approx(8.0, abs=0.01)
    assert flown["separation_time_s"] == pytest.approx(12.4, abs=0.3)
    # What simulate used to do: the passenger on the deck (z = 0), below the altitude floor
    # safety.z_max_m = -0.5, is lifted off the carrier before separation: P1 fails.
    assert not simulate_config(with_overrides(cfg, {"sim.duration_s": 13.0}), flown=False).summary()["p1"]


def test_a_2d_mission_config_is_refused_like_run_refuses_it():
    cfg = load_config(CONFIGS / "paper_2d_obstacles.toml")
    cfg = with_overrides(cfg, {"mission.arrival_radius_m": 0.5})  # now it "has" a [mission] section
    with pytest.raises(ConfigError, match="describes a flight, which needs dim = 3"):
        simulate_config(cfg)


def test_targets_inside_an_obstacle_keepout_are_redrawn():
    # The three scenarios of `--monte-carlo 200 --seed 1` that failed P2 before: each target lay
    # inside an obstacle's keep-out disc (radius + margin), where the CBF never lets the passenger go.
    cfg = load_config(CONFIGS / "paper_2d_obstacles.toml")
    unreachable = np.array([[32.08, 10.911], [22.23, 8.141], [20.832, 6.271]])
    assert not target_reachable(cfg, unreachable).any()
    _, targets = random_scenarios(cfg, 200, seed=1)
    assert target_reachable(cfg, targets).all()
    report = run_monte_carlo(cfg, 200, 1, show_progress=False)
    assert report["fraction_all"] == 1.0 and report["failing"] == 0


def test_monte_carlo_report_names_failing_scenarios_with_ids_and_parameters():
    cfg = with_overrides(load_config(CONFIGS / "paper_3d.toml"), {"sim.duration_s": 1.0, "sim.dt_s": 0.01})
    report = run_monte_carlo(cfg, 12, 3, show_progress=False)  # 1 s: nobody separates
    assert report["failing"] == 12 and len(report["worst_cases"]) == 10
    _, targets = random_scenarios(cfg, 12, seed=3)
    for w in report["worst_cases"]:
        assert w["target"] == pytest.approx(targets[w["index"]].round(3).tolist())
        assert not w["p1"]
    line = format_case(report["worst_cases"][0])
    assert line.startswith(f"  #{report['worst_cases'][0]['index']}") and "separation never" in line and "P1 FAILED" in line
