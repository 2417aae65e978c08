"""Deploy and recover on the mock, end to end: ``marsupial demo --config configs/recovery.toml``
(three processes over real UDP and Zenoh, in lockstep on the mock vehicle's simulated time). The
carrier drives its recovery course at 1.5 m/s while the passenger returns, holds off, approaches
and docks; one flight, shared by the tests that read it."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from mission.config.schema import load_config
from tests.conftest import CONFIGS

pytestmark = pytest.mark.slow

RECOVERY = CONFIGS / "recovery.toml"


@pytest.fixture(scope="module")
def recovery_flight(tmp_path_factory):
    """The demo of configs/recovery.toml: (the pair's log folder, the finished process)."""
    root = tmp_path_factory.mktemp("recovery")
    cmd = [sys.executable, "-m", "mission.cli", "demo", "--config", str(RECOVERY), "--log-root", str(root / "logs"),
           "--plot", "", "--timeout", "150"]
    return root / "logs" / "pair0", subprocess.run(cmd, capture_output=True, text=True, timeout=240)


def test_the_passenger_docks_on_the_moving_carrier_at_the_first_attempt(recovery_flight):
    """The targets on the mock: the carrier at 1-2 m/s on the approach; docked at the first
    attempt, within 0.10 m, at <= 0.2 m/s horizontal and <= 0.5 m/s vertical relative speed; no
    jump above 0.05 m/s at any phase switch; the deck never touched outside contact; P1-P3 on
    the way out and P3 throughout (the carrier's own account too)."""
    log, out = recovery_flight
    assert out.returncode == 0, out.stdout + out.stderr
    s = json.loads((log / "summary.json").read_text())
    assert s["phase"] == "DONE" and s["p1"] and s["p2"] and s["p3"], s
    low, high = s["carrier_speed_on_approach_m_s"]
    assert 1.0 <= low and high <= 2.0, s["carrier_speed_on_approach_m_s"]
    assert s["docked_again"] and s["recovery_outcome"] == "docked", s
    contact = s["contact"]
    assert contact["attempts"] == 1, contact
    assert contact["horizontal_error_m"] <= 0.10, contact
    assert contact["horizontal_relative_speed_m_s"] <= 0.2 and contact["vertical_relative_speed_m_s"] <= 0.5, contact
    assert s["max_phase_switch_jump_m_s"] <= 0.05, s["max_phase_switch_jump_m_s"]
    assert s["deck_violations"] == 0
    guard = load_config(RECOVERY).law.b * load_config(RECOVERY).law.c - load_config(RECOVERY).carrier.p3_margin_m
    assert s["min_carrier_target_distance_m"] >= guard - 1e-3  # the whole flight, as the passenger saw it
    c = json.loads((log / "carrier.json").read_text())
    assert c["closest_target_distance_m"] >= guard - 1e-9 and c["mode"] == "parked", c
    assert s["lockstep"]["fallback"] is None and c["lockstep"]["fallback"] is None


def test_the_demo_table_shows_the_recovery(recovery_flight):
    log, out = recovery_flight
    s = json.loads((log / "summary.json").read_text())
    table = out.stdout
    for label in ("recovery outcome", "approaches flown to the dock (attempts)", "horizontal error at contact [m]",
                  "horizontal relative speed at contact [m/s]", "vertical relative speed at contact [m/s]",
                  "carrier speed on the approach [m/s]", "max command jump at a phase switch [m/s]"):
        assert label in table, table
    row = next(line for line in table.splitlines() if line.startswith("horizontal error at contact"))
    assert row.split()[-1] == f"{s['contact']['horizontal_error_m']:.3f}"
    assert "P1-P3 held, and the passenger docked again" in out.stdout
