"""The team Monte-Carlo's draw (sim/batch/team_mc.py): every scenario drawn satisfies the
assumptions the configuration does not check yet, among them that no two targets' carrier
keep-outs overlap (:func:`keep_outs_apart`); a team whose keep-outs overlap, the wall the carrier
stood behind until the mission's time ran out (#52 of seed 1 before the rule), is refused."""
from __future__ import annotations

import math

import numpy as np

from mission.config.schema import from_dict, load_config
from sim.batch import team_mc
from tests.conftest import CONFIGS

BASE = load_config(CONFIGS / "team.toml").model_dump(exclude_unset=True)


def _team(targets: list[list[float]]):
    data = {key: dict(value) if isinstance(value, dict) else value for key, value in BASE.items()}
    data["scenario"] = {**data["scenario"], "targets": targets}
    data["scenario"].pop("target", None)
    data["team"] = {**data["team"], "passengers": [
        {**p, "targets": [k for k in range(len(targets)) if k % len(BASE["team"]["passengers"]) == j]}
        for j, p in enumerate(BASE["team"]["passengers"])]}
    return from_dict(data)


def test_overlapping_keep_outs_are_refused_apart_ones_drawn():
    # #52's pair: 13.0 m apart horizontally, rows of 7.53 + 0.5 and 6.77 + 0.5 m: they overlap
    near = _team([[-3.79, 24.04, -4.36], [7.53, -29.62, -2.71], [7.65, -16.62, -4.26]])
    assert not team_mc.keep_outs_apart(near)
    far = _team([[-3.79, 24.04, -4.36], [7.53, -29.62, -2.71], [26.38, 4.55, -3.69]])
    assert team_mc.keep_outs_apart(far)
    bc, margin = near.law.params().separation_distance_m, near.safety.margin_m
    for sc in team_mc.scenarios(30, 1, BASE):
        legs = [np.asarray(t, dtype=float) for t in sc.cfg.scenario.legs()]
        rows = [math.sqrt(bc * bc - float(t[2]) ** 2) + margin for t in legs]
        for i in range(len(legs)):
            for j in range(i + 1, len(legs)):
                assert np.hypot(*(legs[i][:2] - legs[j][:2])) >= rows[i] + rows[j]


def test_a_violation_names_its_pair_and_what_their_barriers_saw():
    # the shortfall's moment: true distance, what the count keeps, and the distance of the two
    # positions the vehicles report (the barrier's view): #70 of seed 1 came 0.021 m inside 3 m
    # in truth while the reported positions stayed 3.59 m apart (docs/team.md)
    sc = team_mc.scenarios(1, 1, BASE)[0]
    w = team_mc.TeamWorld(sc.cfg, estimate_error=1.0, seed=sc.seed, batteries=sc.batteries)
    for _ in range(5):
        w.tick()
    a, b = w.members[0], w.members[1]
    t = w.t[-1]
    true = float(np.linalg.norm(a.vehicle.true_position - b.vehicle.true_position))
    worst = team_mc._worst(w, 0, 1, true, 3.0)
    reported = np.linalg.norm(np.asarray(a.vehicle.report(t).position_ned_m) - np.asarray(b.vehicle.report(t).position_ned_m))
    assert worst["pair"] == [a.name, b.name] and worst["phases"] == [a.state.phase.value, b.state.phase.value]
    assert worst["reported_m"] == round(float(reported), 3) and worst["true_m"] == round(true, 3)
    assert worst["reported_m"] != worst["true_m"]  # the estimates err (PX4 SITL's)
    rows = [{"index": 7, "violation": True, "worst_pair": worst}, {"index": 8, "violation": False, "worst_pair": None}]
    assert [v["index"] for v in team_mc.table_violations(rows)] == [7]


def test_the_table_keeps_the_largest_jump_at_a_separation():
    def leg(jump, rel):
        return {"passenger": "p0", "leg": 0, "docked": True, "attempts": 1, "within_2": True, "p1": True, "p2": True,
                "p3": True, "switch_jump_m_s": 0.04, "separation_jump_m_s": jump, "relative_separation_jump_m_s": rel}
    row = {"index": 0, "legs": [leg(0.031, 0.012), leg(None, None), leg(0.044, 0.009)], "pair_min_air_m": 5.0,
           "pair_min_any_m": 1.0, "pair_shortfall_m": 0.0, "violation": False, "touched": False, "queue_switches": 0,
           "queue_step_m_s": 0.0, "carrier_inside_keep_out": False, "low_battery": None}
    t = team_mc.table([row])
    assert t["largest_separation_jump_m_s"] == 0.044 and t["largest_relative_separation_jump_m_s"] == 0.012
