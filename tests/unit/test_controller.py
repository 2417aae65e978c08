"""The mission loop and its command worker on a fake world (no sockets, manual clock)."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from mission.time.clock import ManualClock
from mission.config.schema import load_config, with_overrides
from mission.controller import MissionController, TickReport
from mission.mavlink.requests import CommandWorker
from mission.record.info import mission_info
from mission.errors import LinkError
from mission.core.law import norm
from mission.phases import AbortReason, Phase
from mission.phases.phase import Request
from mission.record.recorder import FlightRecorder
from tests.conftest import CONFIGS
from tests.support.fake_vehicle import FakeWorld


@pytest.fixture(scope="module")
def cfg():
    return load_config(CONFIGS / "demo.toml")


def fly(cfg, **world_kwargs):
    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(cfg.scenario.target, dtype=float), **world_kwargs)
    reports: list[TickReport] = []
    controller = MissionController(cfg, world, world.feed, clock, publisher=world, on_tick=reports.append,
                                   command_thread=False)
    outcome = controller.run()
    return outcome, world, reports, controller


@pytest.fixture(scope="module")
def whole_mission(cfg):
    """demo.toml's mission on the fake vehicle, flown once for the tests that read it."""
    return fly(cfg)


def test_whole_mission_on_the_fake_vehicle(cfg, whole_mission):
    outcome, world, reports, controller = whole_mission
    assert outcome.ok, (outcome.reason, outcome.detail)
    phases = list(dict.fromkeys(r.phase for r in reports))
    assert phases == [Phase.STREAMING, Phase.ARMING, Phase.OFFBOARD, Phase.JOIN, Phase.RIDING, Phase.SEPARATED,
                      Phase.NAVIGATING, Phase.ARRIVED, Phase.HOLD, Phase.DONE]
    # commands in order, each once: arm, offboard, and the final Hold
    assert [name for _, name in world.commands] == ["arm", "OFFBOARD", "AUTO.LOITER"]
    # the passenger ends within the arrival radius; the separation latched with the dock at b*c
    # from the target, and the carrier (stopped by the passenger's status) went one tick further
    target = np.asarray(cfg.scenario.target, dtype=float)
    assert norm(world.vehicle_ned_m - target) <= cfg.mission.arrival_radius_m
    bc = cfg.law.params().separation_distance_m
    assert norm(target - controller.state.anchor) == pytest.approx(bc - cfg.law.departure_margin_m, abs=1e-9)
    dock = world.carrier_ned_m + np.asarray(cfg.mission.dock_offset_ned_m)
    assert bc - 2 * world.carrier_speed_m_s / cfg.mission.rate_hz <= norm(target - dock) <= bc
    # one setpoint per tick that decided one, at the mission rate, all finite
    sent = [r for r in reports if r.decision.setpoint is not None]
    assert len(world.setpoints) == len(sent) > 0
    times = np.array([t for t, _ in world.setpoints])
    assert np.allclose(np.diff(times[:50]), 1.0 / cfg.mission.rate_hz)
    assert all(np.isfinite(v).all() for _, v in world.setpoints)
    # the status went out every tick with a vehicle, and says separated after the latch
    assert world.statuses[-1].separated and world.statuses[-1].phase == "DONE"
    assert controller.ticks == len(reports)


def test_tick_report_stamps_only_ticks_that_sent(whole_mission):
    _, _, reports, _ = whole_mission
    for r in reports:
        assert r.start_ns <= r.observed_ns
        if r.decision.setpoint is None:
            assert r.send_ns == r.sent_ns == 0
        else:
            assert r.observed_ns <= r.send_ns <= r.sent_ns
    assert any(r.carrier is not None and r.carrier.value.seq > 0 for r in reports)


def test_arming_refused_aborts_with_the_vehicles_reason(cfg):
    outcome, world, reports, _ = fly(cfg, refuse={"arm": "Arming denied: resolve system health failures first"})
    assert outcome.phase == "ABORT" and outcome.reason == AbortReason.ARMING_REFUSED
    assert "resolve system health" in outcome.detail
    assert [name for _, name in world.commands].count("arm") == cfg.mission.command_retries
    assert not world.armed


def test_offboard_refused_aborts(cfg):
    outcome, world, _, _ = fly(cfg, refuse={"OFFBOARD": "Switching to Offboard is currently not available"})
    assert outcome.reason == AbortReason.OFFBOARD_REFUSED
    assert world.mode != "OFFBOARD"


def test_vehicle_silent_while_riding_aborts_as_lost(cfg):
    outcome, world, reports, _ = fly(cfg, heartbeat_until_s=8.0)
    assert outcome.reason == AbortReason.VEHICLE_LOST
    lost_at = next(r.t_s for r in reports if r.phase == Phase.ABORT)
    assert lost_at == pytest.approx(8.0 + cfg.mission.heartbeat_timeout_s, abs=2.0 / cfg.mission.rate_hz)


def test_carrier_silent_before_separation_aborts(cfg):
    outcome, world, reports, _ = fly(cfg, carrier_until_s=12.0)
    assert outcome.reason == AbortReason.CARRIER_LOST
    # the abort asks for Hold and the fake shows it
    assert world.mode == "AUTO.LOITER"


def test_final_land(cfg):
    outcome, world, _, _ = fly(with_overrides(cfg, {"mission.final_action": "land"}))
    assert outcome.ok and world.mode == "AUTO.LAND"


class FlakyVehicle:
    """Fails ``arm`` with a link error ``failures`` times, then accepts."""

    def __init__(self, failures: int) -> None:
        self.failures, self.calls = failures, 0

    def arm(self) -> None:
        self.calls += 1
        if self.calls <= self.failures:
            raise LinkError("no COMMAND_ACK")


def test_command_worker_retries_then_succeeds():
    clock, vehicle = ManualClock(), FlakyVehicle(failures=2)
    worker = CommandWorker(vehicle, clock, retries=3, threaded=False)  # type: ignore[arg-type]
    worker.submit(Request.ARM)
    assert vehicle.calls == 3 and worker.failed == {}
    assert clock.now() == pytest.approx(1.0)  # 0.5 s between tries, on the injected clock


def test_command_worker_gives_up_and_remembers():
    clock, vehicle = ManualClock(), FlakyVehicle(failures=10)
    worker = CommandWorker(vehicle, clock, retries=3, threaded=False)  # type: ignore[arg-type]
    worker.submit("arm")
    assert worker.failed == {"arm": "no COMMAND_ACK"} and vehicle.calls == 3
    worker.submit("arm")  # a failed request is not tried again
    assert vehicle.calls == 3


def test_command_worker_repeats_only_after_repeat_s():
    clock, vehicle = ManualClock(), FakeWorld(ManualClock(), target_ned_m=np.zeros(3))
    worker = CommandWorker(vehicle, clock, repeat_s=2.0, threaded=False)
    worker.submit("hold")
    clock.advance(1.0)
    worker.submit("hold")
    assert len(vehicle.commands) == 1
    clock.advance(1.5)
    worker.submit("hold")
    assert len(vehicle.commands) == 2


def test_threaded_worker_runs_off_the_caller():
    clock, vehicle = ManualClock(), FlakyVehicle(failures=0)
    worker = CommandWorker(vehicle, clock, threaded=True)  # type: ignore[arg-type]
    try:
        worker.submit("arm")
    finally:
        worker.close()  # drains the queue first
    assert vehicle.calls == 1


def test_a_vehicle_disarmed_while_riding_ends_the_stream_and_tells_the_carrier_why(cfg):
    """Someone disarms the vehicle while it rides: on the tick that sees it the mission aborts
    vehicle_disarmed, sends no setpoint and no command from then on, and its last published status
    is ABORT with that reason (the carrier stops on it). It asked for PX4's landed state at 10 Hz."""
    from mission.mavlink.requests import EXTENDED_SYS_STATE_ID, LANDED_STATE_RATE_HZ

    outcome, world, reports, _ = fly(cfg, disarmed_at_s=8.0)
    assert (outcome.phase, outcome.reason) == ("ABORT", AbortReason.VEHICLE_DISARMED.value)
    riding = [r.t_s for r in reports if r.phase == Phase.RIDING]
    assert riding and riding[0] < 8.0 <= reports[-1].t_s < 8.0 + 1.5 / cfg.mission.rate_hz
    assert world.setpoints[-1][0] < 8.0 and [name for _, name in world.commands] == ["arm", "OFFBOARD"]
    last = world.statuses[-1]
    assert (last.phase, last.reason) == ("ABORT", "vehicle_disarmed")
    assert all(s.reason is None for s in world.statuses[:-1])
    assert (EXTENDED_SYS_STATE_ID, LANDED_STATE_RATE_HZ) in world.intervals


class CorruptWorld(FakeWorld):
    """From ``corrupt_after_s`` [s] on, the vehicle's position reads infinite (a corrupt estimate)."""

    corrupt_after_s = 8.0

    @property
    def state(self):  # type: ignore[no-untyped-def]
        st = super().state
        if st.t_s > self.corrupt_after_s:
            return dataclasses.replace(st, position_ned_m=np.array([np.inf, 0.0, -1.5]))
        return st


def test_a_non_finite_value_in_the_loop_aborts_to_hold_with_the_summary_written(cfg, tmp_path):
    """On main an unsaturated law reached "refusing non-finite position setpoint 9e74" in the link:
    a traceback, no summary.json. Now the tick that would hold a NaN or infinity aborts
    (nonfinite, naming it), asks for Hold, and the flight log is complete."""
    clock = ManualClock()
    world = CorruptWorld(clock, target_ned_m=np.asarray(cfg.scenario.target, dtype=float))
    recorder = FlightRecorder(tmp_path / "log", mission_info(cfg))
    outcome = MissionController(cfg, world, world.feed, clock, publisher=world, recorder=recorder, command_thread=False).run()
    assert (outcome.phase, outcome.reason) == ("ABORT", AbortReason.NONFINITE.value), outcome.detail
    assert "non-finite" in outcome.detail and "in RIDING" in outcome.detail
    assert all(np.isfinite(v).all() for _, v in world.setpoints)  # nothing non-finite ever went out
    assert world.commands[-1][1] == "AUTO.LOITER"  # Hold asked
    summary = json.loads((tmp_path / "log" / "summary.json").read_text())
    assert (summary["phase"], summary["reason"]) == ("ABORT", "nonfinite")
