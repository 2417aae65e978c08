"""``marsupial simulate`` of a mission config of one target flies the whole mission
(sim/batch/recovery.py), not the paper's law alone, and says so; the paper's configs keep the
paper's closed loop and say that."""
from __future__ import annotations

import json

import pytest

from mission.cli import main
from mission.config.schema import load_config
from tests.conftest import CONFIGS

pytestmark = pytest.mark.timeout(600)  # a whole mission in-process: seconds of CPU, longer on a busy machine


def test_a_mission_that_holds_at_its_target_is_flown_whole(capsys):
    """configs/demo.toml (final_action "hold"): JOIN, riding, the separation at b c, the target,
    Hold: DONE; the carrier kept behind its guard (b c - carrier.p3_margin_m) all flight."""
    code = main(["simulate", str(CONFIGS / "demo.toml"), "--json"])
    s = json.loads(capsys.readouterr().out)
    cfg = load_config(CONFIGS / "demo.toml")
    assert code == 0 and s["simulated"] == "mission" and s["phase"] == "DONE", s
    assert s["p1"] and s["p2"] and s["p3"]
    assert abs(s["carrier_target_distance_at_separation_m"] - cfg.law.b * cfg.law.c) <= 0.01
    assert s["min_carrier_target_distance_m"] >= cfg.law.b * cfg.law.c - cfg.carrier.p3_margin_m - 1e-3
    assert s["riding_start_s"] > 0  # JOIN was flown before the riding


def test_the_table_says_the_mission_was_flown(capsys):
    code = main(["simulate", str(CONFIGS / "demo.toml"), "--no-progress"])
    out, err = capsys.readouterr()
    assert code == 0 and "has a [mission] section: simulating the whole mission" in err
    assert out.splitlines()[-1].startswith("simulated: mission")
    assert "P1 separation" in out


def test_the_papers_configs_keep_the_papers_law(capsys):
    code = main(["simulate", str(CONFIGS / "paper_3d.toml"), "--json"])
    s = json.loads(capsys.readouterr().out)
    assert code == 0 and s["simulated"] == "paper" and "phase" not in s
    assert s["separation_time_s"] == pytest.approx(2.40, abs=0.01)


def test_a_one_target_mission_on_a_carrier_it_does_not_model_keeps_the_papers_law(capsys, tmp_path):
    """configs/px4_sitl_rover.toml (an Ackermann rover): the mission simulation drives only the
    built-in holonomic carrier, so one target is the paper's closed loop of what `run` flies, as
    before, and the output says so (several targets are refused: test_simulate_legs.py). Its law
    integrated at 10 ms instead of 1 ms: the routing is what is tested, in seconds."""
    path = tmp_path / "rover.toml"
    path.write_text((CONFIGS / "px4_sitl_rover.toml").read_text() + "\n[sim]\ndt_s = 0.01\n")
    code = main(["simulate", str(path), "--no-progress"])
    out, err = capsys.readouterr()
    assert code == 0 and "carrier.kinematics = 'ackermann'" in err and "paper's closed loop" in err, err
    assert out.splitlines()[-1].split() == ["simulated", "paper"]
