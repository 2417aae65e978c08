"""A lockstep demo whose run did not stay in step fails loudly: exit 1, and a verdict line saying
the run was not lockstep and why, whatever P1-P3 say (sim/demo.py, ``not_lockstep``)."""
from __future__ import annotations

from sim.demo import exit_code, not_lockstep, verdict_lines

HELD = {"barriers": 1685, "fallback": None, "downstream_dropped": 0, "downstream_rejoined": 0, "samples_lost": 0,
        "held": True}
PAIR = {"pair": "pair0", "p1": True, "p2": True, "p3": True, "mission_exit_code": 0, "phase": "DONE",
        "lockstep": HELD, "carrier_lockstep": {**HELD, "barriers": 720}}


def _pair(**changes: dict) -> dict:
    s = {**PAIR, **changes}
    return {**s, "not_lockstep": not_lockstep(s)}


def test_a_run_that_stayed_in_step_passes() -> None:
    s = _pair()
    assert s["not_lockstep"] is None and exit_code([s]) == 0 and verdict_lines([s]) == []


def test_a_dropped_carrier_fails_the_demo_even_when_it_rejoined() -> None:
    s = _pair(lockstep={**HELD, "downstream_dropped": 1, "downstream_rejoined": 1, "held": False})
    assert s["not_lockstep"] == "the carrier was dropped 1 time(s) (rejoined 1)"
    assert exit_code([s]) == 1
    assert verdict_lines([s]) == ["pair0: the run was NOT lockstep (the carrier was dropped 1 time(s) (rejoined 1)): "
                                  "its figures prove nothing"]


def test_a_clock_on_the_wall_clock_fails_the_demo() -> None:
    carrier = _pair(carrier_lockstep={**HELD, "fallback": "upstream silent for 6.1 s (wall)"})
    assert "the carrier's clock fell back to the wall clock (upstream silent" in carrier["not_lockstep"]
    mission = _pair(lockstep={**HELD, "fallback": "upstream silent for 5.0 s (wall)", "held": False})
    assert "the mission's clock fell back" in mission["not_lockstep"]
    never = _pair(lockstep={**HELD, "barriers": 0, "held": False})
    assert never["not_lockstep"] == "the mission never stepped in lockstep"
    robot = _pair(carrier_lockstep={**HELD, "downstream_dropped": 1, "held": False})
    assert robot["not_lockstep"] == "the carrier's robot was dropped 1 time(s)"
    assert exit_code([carrier]) == exit_code([mission]) == exit_code([never]) == exit_code([robot]) == 1
