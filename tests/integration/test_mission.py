"""The mission controller against the mock vehicle (UDP) and the carrier simulator (Zenoh).

Each test flies a whole pair at 5x real time and asserts on behaviour and numbers: P1-P3 from the
flight log, the smoothness of the relative command at separation, and one defined reaction per
failsafe (docs/safety.md's table). Timeouts scale with the speed: at 5x, PX4's 1 s
offboard-loss timeout is 0.2 s of wall time, which a loaded 2-core CI machine still keeps.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from mission.mavlink.env import mavutil

from mission.record.table import read_record
from mission.phases import AbortReason, Phase
from sim.vehicle.mock import FaultOptions
from tests.support.mission_harness import flying_pair, wait_for

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def full_mission(tmp_path_factory):
    """One whole mission flown on the mock vehicle, shared by the tests that read its outcome."""
    with flying_pair(tmp_path_factory.mktemp("full")) as pair:
        out = pair.finish()
        snap = pair.vehicle.snapshot()
    return pair, out, snap, json.loads((pair.log_dir / "summary.json").read_text())


def test_full_mission_p2_p3_and_smooth_separation(full_mission):
    pair, out, snap, s = full_mission
    assert out.phase == "DONE", (out.reason, out.detail)
    assert s["p2"] and s["p3"]
    bc = pair.cfg.law.b * pair.cfg.law.c
    assert s["carrier_target_distance_at_separation_m"] == pytest.approx(bc, abs=0.01)
    # Smooth separation: the commanded velocity relative to the carrier changes by no more than a
    # tick of the acceleration limit across the event (an event-based switch would jump by the
    # carrier's speed, 2 m/s here).
    assert s["relative_input_jump_m_s"] < 0.15
    assert s["max_relative_command_step_m_s"] < 0.5
    assert s["final_passenger_target_distance_m"] <= pair.cfg.mission.arrival_radius_m
    assert s["min_carrier_target_distance_m"] > 0.5 * bc  # P3 with margin: the carrier brakes short
    # the vehicle ends in Hold, armed, in the air at the target
    assert snap.mode == "AUTO.LOITER" and snap.armed
    assert np.linalg.norm(snap.position_ned_m - np.array(pair.cfg.scenario.target)) < 1.0


def test_full_mission_p1_holds_the_dock(full_mission):
    _, _, _, s = full_mission
    assert s["max_offset_before_separation_m"] <= 0.5
    assert s["p1"]


def test_flight_log_is_complete_and_tlog_readable(full_mission):
    pair, out, _, _ = full_mission
    assert out.phase == "DONE", (out.reason, out.detail)
    rec = read_record(pair.log_dir)
    phases_seen = [p for p in dict.fromkeys(rec.phase) if p != "PREFLIGHT"]  # the record holds each tick's outcome
    assert phases_seen == ["STREAMING", "ARMING", "OFFBOARD", "JOIN", "RIDING", "SEPARATED", "NAVIGATING",
                           "ARRIVED", "HOLD", "DONE"]
    sent = rec.vec("u_cmd")
    assert np.isfinite(sent[~np.isnan(sent).all(axis=1)]).all()  # never NaN/inf when something was sent
    log = mavutil.mavlink_connection(str(pair.log_dir / "flight.tlog"))
    types = set()
    while (m := log.recv_match(blocking=False)) is not None:
        types.add(m.get_type())
    log.close()
    assert {"HEARTBEAT", "SET_POSITION_TARGET_LOCAL_NED", "LOCAL_POSITION_NED", "COMMAND_LONG", "COMMAND_ACK"} <= types


def test_pilot_override_stops_commanding(tmp_path):
    with flying_pair(tmp_path) as pair:
        pair.wait_phase(Phase.RIDING)
        t_override = pair.vehicle.clock.now()
        pair.vehicle.force_mode("POSCTL")
        out = pair.finish()
        snap = wait_for(pair.vehicle.when(lambda s: s.t_s > t_override + 2.0), 5.0, "s.t_s > t_override + 2.0")
        assert snap is not None
        # the controller learns the mode from the 1 Hz HEARTBEAT, as with PX4: no setpoint reached
        # the vehicle later than one HEARTBEAT period (plus a few ticks) after the takeover
        assert snap.last_setpoint_t_s is not None and snap.last_setpoint_t_s < t_override + 1.2
        assert snap.mode == "POSCTL"  # never switched back
    assert out.reason == AbortReason.PILOT_OVERRIDE.value and "POSCTL" in out.detail


def test_carrier_stale_before_separation_holds(tmp_path):
    with flying_pair(tmp_path) as pair:
        pair.wait_phase(Phase.RIDING)
        pair.stop_carrier()
        out = pair.finish()
        snap = pair.vehicle.snapshot()
    assert out.reason == AbortReason.CARRIER_LOST.value
    assert snap.mode == "AUTO.LOITER" and snap.armed  # Hold, never disarmed in the air
    assert snap.position_ned_m[2] < -0.5


def test_carrier_lost_after_separation_mission_continues(tmp_path):
    with flying_pair(tmp_path) as pair:
        pair.wait_phase(Phase.NAVIGATING)
        pair.stop_carrier()
        pair.carrier.close()  # liveliness token gone too
        out = pair.finish()
    assert out.phase == "DONE"
    assert out.summary["p2"]


def test_vehicle_heartbeat_lost_aborts_and_px4_fails_safe(tmp_path):
    with flying_pair(tmp_path) as pair:
        pair.wait_phase(Phase.RIDING)
        t = pair.vehicle.clock.now()
        pair.vehicle.set_faults(blackouts=[(t, 30.0)])
        out = pair.finish()
        # without setpoints the vehicle's own failsafe takes it out of OFFBOARD (COM_OBL_RC_ACT 0)
        wait_for(lambda: pair.vehicle.snapshot().mode == "POSCTL", timeout_s=5.0, what="PX4 offboard-loss failsafe")
    assert out.reason == AbortReason.VEHICLE_LOST.value


def test_arming_refused_reports_vehicle_reason(tmp_path):
    reason = "Arming denied: Resolve system health failures first"
    with flying_pair(tmp_path, start=False) as pair:
        pair.vehicle.refuse_arming(reason)
        pair.thread.start()
        out = pair.finish()
        assert not pair.vehicle.snapshot().armed
    assert out.reason == AbortReason.ARMING_REFUSED.value
    assert "Arming denied" in out.detail


def test_offboard_refused_after_retries(tmp_path):
    # The vehicle refuses OFFBOARD (TEMPORARILY_REJECTED with a STATUSTEXT reason).
    with flying_pair(tmp_path, vehicle={"faults": FaultOptions(refuse_offboard_reason="Mode OFFBOARD rejected: test")}) as pair:
        out = pair.finish()
        snap = pair.vehicle.snapshot()
    assert out.reason == AbortReason.OFFBOARD_REFUSED.value and "rejected" in out.detail
    assert snap.mode != "OFFBOARD"


def test_geometry_violation_refuses_to_start_and_sends_nothing(tmp_path):
    # The passenger is 5 m away from the carrier: Assumption 2 fails on the live states.
    with flying_pair(tmp_path, vehicle={"start_ned": (5.0, 0.0, 0.0)}) as pair:
        out = pair.finish()
        counters = pair.vehicle.counters
        snap = pair.vehicle.snapshot()
    assert out.reason == AbortReason.GEOMETRY.value and "Assumption 2" in out.detail
    assert pair.link.counters.tx_setpoints == 0 and pair.link.counters.tx_commands == 0
    assert counters.get("setpoints_accepted", 0) == 0 and not snap.armed


def test_interrupt_holds_and_never_disarms(tmp_path):
    with flying_pair(tmp_path) as pair:
        pair.wait_phase(Phase.RIDING)
        pair.controller.stop.set()
        out = pair.finish()
        snap = pair.vehicle.snapshot()
    assert out.reason == AbortReason.INTERRUPTED.value
    assert snap.mode == "AUTO.LOITER" and snap.armed


def test_position_estimate_lost_aborts(tmp_path):
    with flying_pair(tmp_path) as pair:
        pair.wait_phase(Phase.RIDING)
        pair.vehicle.lose_position_estimate(True)
        out = pair.finish()
    # PX4 exits OFFBOARD for its own failsafe; the mission stops commanding and says so.
    assert out.reason in (AbortReason.POSITION_LOST.value, AbortReason.VEHICLE_FAILSAFE.value)
