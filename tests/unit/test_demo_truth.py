"""The demo reports the world's truth beside the mission's belief: a deck crash recorded by the
mock vehicle (``mock-vehicle --summary``) says "crash" and makes the demo exit 1, whatever the
mission's summary claimed (sim/demo.py)."""
from __future__ import annotations

import json
from pathlib import Path

from sim.demo import deck_truth, exit_code, format_table, outcome_text, verdict_lines

BELIEF = {"pair": "pair0", "p1": True, "p2": True, "p3": True, "mission_exit_code": 0, "phase": "DONE",
          "docked_again": True, "recovery_outcome": "docked", "contact": {"horizontal_error_m": 0.0758}}


def _truth(tmp_path: Path, crash: str | None, error_m: float) -> Path:
    path = tmp_path / "vehicle.json"
    start = {"t_s": 0.1, "horizontal_error_m": 0.0, "vertical_speed_m_s": 0.0, "horizontal_speed_m_s": 0.0, "crash": None}
    landing = {"t_s": 40.9, "horizontal_error_m": error_m, "vertical_speed_m_s": 0.04, "horizontal_speed_m_s": 0.15,
               "crash": crash}
    path.write_text(json.dumps({"t_s": 50.0, "deck": {"crash": crash, "on_deck": True, "touchdowns": [start, landing]}}))
    return path


def test_a_crash_on_the_deck_overrides_the_missions_dock_and_fails_the_demo(tmp_path):
    crash = "off the deck's edge: 0.67 m from its centre (radius 0.5 m)"
    s = {**BELIEF, **deck_truth(_truth(tmp_path, crash, 0.6727))}
    assert s["deck_crash"] == crash and s["deck_touchdown_m"] == 0.6727 and s["docked_again"] is False
    assert s["recovery_outcome"] == f"crash: {crash}"
    assert outcome_text(s) == "crash (0)"
    assert exit_code([s]) == 1
    assert any("CRASHED" in line and "0.0758" in line for line in verdict_lines([s]))
    table = format_table([s])
    assert "truth: last touchdown from the deck's centre [m]" in table and "0.673" in table


def test_a_landing_on_the_deck_is_reported_beside_the_contact_and_passes(tmp_path):
    s = {**BELIEF, **deck_truth(_truth(tmp_path, None, 0.04))}
    assert s["deck_crash"] is None and s["deck_touchdown_m"] == 0.04 and s["recovery_outcome"] == "docked"
    assert exit_code([s]) == 0 and outcome_text(s) == "done (0)"
    assert deck_truth(tmp_path / "missing.json") == {}  # no truth (a real vehicle): the mission's account alone
