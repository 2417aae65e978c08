"""The recovery's Monte-Carlo (sim/batch/recovery.py, recovery_mc.py): a small sample meets the targets, a
scenario replays, the shared flight before the recovery changes nothing, and its vehicle is the
mock's (the comparison with a lockstep demo flight: tests/integration/test_recovery_mc.py)."""
from __future__ import annotations

import numpy as np
import pytest

from mission.config.schema import load_config
from mission.phases.phase import Request
from mission.core.setpoint import Setpoint
from mission.time.clock import ManualClock
from sim.batch.recovery import MockDynamics, Scenario, before_recovery, fly
from sim.batch.recovery_mc import DOCKED_WITHIN_2_TARGET, format_report, monte_carlo, random_scenarios, report_ok
from sim.vehicle.mock import PHYSICS_DT_S, MockVehicle, VehicleOptions
from sim.vehicle.protocol import setpoint_of
from mission.mavlink import setpoints
from tests.conftest import CONFIGS

pytestmark = pytest.mark.timeout(600)  # whole missions in-process: seconds of CPU each, longer on a busy machine


@pytest.fixture(scope="module")
def cfg():
    return load_config(CONFIGS / "recovery.toml")


def test_a_sample_of_recoveries_meets_the_targets(cfg):
    """10 random scenarios (carrier 0-2 m/s, any heading, a turn of up to 45 deg during the first
    approach) and one turn held long enough to be found (30 deg at 25 deg/s, 2 s into the first
    approach: the go-around 0.74 s after it began, docked at the second approach): every one
    docked within 2 attempts, none touched the deck outside the contact conditions, no command
    jump at a switch, P3 held. The full 200: bench/recovery_mc.py.

    The random ten sent two round again when the turn check differenced two samples 0.25 s apart:
    7.8 deg at 23.4 deg/s (0.33 s) and 14.2 deg at 22.1 deg/s (0.64 s). Over the 1 s window of
    recovery.carrier_rate_window_s those read at most 11 and 18 deg/s (a turn held d of the window
    reads at most 1.5 d - 0.5 d^3 of its rate), and both docked at the first approach within the
    contact conditions; so the held turn is added to keep a go-around in the sample."""
    held = Scenario(speed_m_s=1.0, heading_deg=155.0, turn_deg=30.0, turn_rate_deg_s=25.0, turn_after_s=2.0, index=10)
    report, worst = monte_carlo(cfg, [*random_scenarios(10, seed=3), held])
    d = report.as_dict()
    assert report.docked_within_2 >= DOCKED_WITHIN_2_TARGET, format_report(report)
    assert report.unsafe == [] and d["deck_violations"] == 0 and d["true_deck_violations"] == 0
    assert report_ok(report)
    assert d["contact"]["horizontal_error_m"]["max"] <= cfg.recovery.contact_radius_m
    assert d["contact"]["horizontal_relative_speed_m_s"]["max"] <= cfg.recovery.contact_max_horizontal_speed_m_s
    assert d["max_phase_switch_jump_m_s"] <= 0.05 and d["p3"]
    assert any(r["attempts"] == 2 for r in report.rows)  # a turn sent one round again: the sample tests go-arounds
    assert set(d["go_arounds"]) <= {"the carrier turns at x deg/s", "x m off the glide path"}, d["go_arounds"]
    assert worst is not None and worst.attempts == max(r["attempts"] for r in report.rows)
    assert "docked within 2 attempts" in format_report(report)


def test_the_same_seed_gives_the_same_scenarios():
    a, b = random_scenarios(20, seed=7), random_scenarios(20, seed=7)
    assert a == b and a != random_scenarios(20, seed=8)
    speeds = np.array([s.speed_m_s for s in random_scenarios(500, seed=1)])
    turns = np.array([s.turn_deg for s in random_scenarios(500, seed=1)])
    assert speeds.min() >= 0.0 and speeds.max() <= 2.0 and np.abs(turns).max() <= 45.0


def test_a_scenario_course_turns_after_the_approach_began():
    sc = Scenario(speed_m_s=1.0, heading_deg=90.0, turn_deg=-30.0, turn_rate_deg_s=10.0, turn_after_s=2.0)
    assert sc.course_heading_deg(None) == 90.0 and sc.course_heading_deg(2.0) == 90.0
    assert sc.course_heading_deg(3.0) == pytest.approx(80.0) and sc.course_heading_deg(60.0) == pytest.approx(60.0)


def test_sharing_the_flight_before_the_recovery_changes_nothing(cfg):
    """A batch flies the mission up to the recovery once and branches every scenario from there:
    the same record, tick for tick, as flying the scenario from the start."""
    sc = Scenario(speed_m_s=1.2, heading_deg=200.0, turn_deg=25.0, turn_rate_deg_s=15.0, turn_after_s=1.0)
    whole = fly(cfg, sc)
    shared = before_recovery(cfg)
    branched = shared.copy().with_scenario(sc).run().flight()
    assert whole.summary == branched.summary and whole.docked
    for key, column in whole.record.cols.items():
        np.testing.assert_array_equal(column, branched.record.cols[key], err_msg=key)
    with pytest.raises(ValueError, match="only before"):
        branched_world = shared.copy().with_scenario(sc).run(lambda w: w.carrier.course_begun)
        branched_world.with_scenario(sc)


def test_the_vehicle_is_the_mocks(cfg):
    """MockDynamics steps the mock's commander and physics as MockVehicle does: the same setpoints
    (arm, OFFBOARD, a climb and a dash) give the same true state, bit for bit."""
    start = (1.0, 2.0, 0.0)
    mine = MockDynamics(start)
    theirs = MockVehicle(VehicleOptions(start_ned=start, estimate_error=0.0), clock=ManualClock())  # never started: no socket
    plan = [Setpoint(np.array([0.0, 0.0, -1.0]))] * 60 + [
        Setpoint(np.array([1.5, -0.5, 0.0]), np.array([3.0, 1.0, -2.0]), np.array([0.5, 0.0, 0.0]))] * 200
    for k, sp in enumerate(plan):
        t = k * 0.02
        mine.advance_to_step(k * 4)
        theirs._advance_steps(k * 4)  # as its lockstep stepper brings it to a barrier
        mine.send(t, sp)
        trajectory, _ = setpoint_of(setpoints.encode(sp, (1, 1), int(t * 1000)), 0.0)
        theirs._commander.accept_setpoint(theirs._t_s, trajectory)
        if k == 25:
            assert mine.request(t, Request.ARM) is None and theirs._commander.arm(t) == 0
        if k == 30:
            assert mine.request(t, Request.OFFBOARD) is None and theirs._commander.set_mode(t, "OFFBOARD") == 0
    mine.advance_to_step(len(plan) * 4)
    theirs._advance_steps(len(plan) * 4)
    assert PHYSICS_DT_S * 4 == pytest.approx(0.02)
    assert theirs._commander.mode == "OFFBOARD" and mine.commander.mode == "OFFBOARD"
    assert mine.kin == theirs._kin
    assert float(np.linalg.norm(mine.true_position - np.array([1.0, 2.0, 0.0]))) > 3.0  # it flew
