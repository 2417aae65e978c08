"""Bringing the passenger home on the fake world (no sockets, manual clock): the phases, their
switches without a jump, the contact, go-arounds, the fallback and the battery's recall."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mission.config.schema import load_config, with_overrides
from mission.controller import MissionController, TickReport
from mission.core.law import norm
from mission.phases import Phase
from mission.phases.phase import RECOVERY
from mission.time.clock import ManualClock
from tests.conftest import CONFIGS
from tests.support.fake_vehicle import FakeWorld


@pytest.fixture(scope="module")
def cfg():
    return with_overrides(load_config(CONFIGS / "demo.toml"), {"mission.final_action": "return", "mission.at_target_s": 2.0,
                                                               "mission.max_duration_s": 600.0})


def fly(cfg, **world_kwargs):
    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(cfg.scenario.target, dtype=float), **world_kwargs)
    reports: list[TickReport] = []
    controller = MissionController(cfg, world, world.feed, clock, publisher=world, on_tick=reports.append,
                                   command_thread=False)
    outcome = controller.run()
    return outcome, world, reports, controller


def phase_order(reports: list[TickReport]) -> list[Phase]:
    order = [reports[0].phase]
    for r in reports[1:]:
        if r.phase != order[-1]:
            order.append(r.phase)
    return order


def switch_jumps(reports: list[TickReport]) -> dict[str, float]:
    """{"A->B": |change of the commanded velocity| at that switch} [m/s], over the flying phases."""
    out = {}
    sent = [r for r in reports if r.decision.setpoint is not None]
    for a, b in zip(sent, sent[1:]):
        if a.phase != b.phase and a.phase.flying and b.phase.flying:
            jump = float(norm(b.decision.setpoint.velocity_ned_m_s - a.decision.setpoint.velocity_ned_m_s))
            out[f"{a.phase}->{b.phase}"] = max(out.get(f"{a.phase}->{b.phase}", 0.0), jump)
    return out


def test_return_and_dock_on_a_moving_carrier(cfg):
    course = np.array([1.2, -0.9, 0.0])  # 1.5 m/s
    outcome, world, reports, controller = fly(cfg, recovery_velocity_ned_m_s=course)
    assert outcome.ok, (outcome.reason, outcome.detail)
    order = phase_order(reports)
    assert order[order.index(Phase.ARRIVED):] == [Phase.ARRIVED, Phase.RETURNING, Phase.HOLDOFF, Phase.APPROACH,
                                                  Phase.DOCKED, Phase.HOME, Phase.HOLD, Phase.DONE], order
    rec = controller.state.recovery
    assert rec is not None and rec.attempts == 1 and rec.contact is not None
    g = cfg.recovery
    assert rec.contact["horizontal_error_m"] <= 0.10
    assert rec.contact["horizontal_relative_speed_m_s"] <= g.contact_max_horizontal_speed_m_s
    assert rec.contact["vertical_relative_speed_m_s"] <= g.contact_max_vertical_speed_m_s
    # no phase switch moved the commanded velocity by more than the reference's acceleration * tick
    jumps = switch_jumps(reports)
    assert set(jumps) >= {"ARRIVED->RETURNING", "RETURNING->HOLDOFF", "HOLDOFF->APPROACH", "APPROACH->DOCKED"}
    assert max(jumps.values()) <= 0.05, jumps
    # home: the vehicle sits on the dock point of a carrier that moved on and parked
    dock = world.carrier_ned_m + np.asarray(cfg.mission.dock_offset_ned_m)
    assert norm(world.vehicle_ned_m - dock) <= 0.15
    target = np.asarray(cfg.scenario.target, dtype=float)
    assert norm((world.carrier_ned_m - target)[:2]) > cfg.law.b * cfg.law.c - cfg.carrier.p3_margin_m  # P3
    # PX4's home followed the carrier while flying
    homes = [r.decision.home_ned_m for r in reports if r.decision.home_ned_m is not None]
    assert len(homes) > 100 and norm(homes[-1] - world.carrier_ned_m) < 0.5


def test_a_turning_carrier_sends_the_passenger_round_again(cfg):
    """The carrier swings its course by 90 deg during the first approach: go around, approach again, dock."""
    turned = {"done": False}

    def turn(world: FakeWorld, report: TickReport) -> None:
        if report.phase is Phase.APPROACH and not turned["done"]:
            world.recovery_velocity_ned_m_s = np.array([0.9, 1.2, 0.0])
            turned["done"] = True

    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(cfg.scenario.target, dtype=float),
                      recovery_velocity_ned_m_s=np.array([1.2, -0.9, 0.0]))
    reports: list[TickReport] = []

    def on_tick(r: TickReport) -> None:
        reports.append(r)
        turn(world, r)

    controller = MissionController(cfg, world, world.feed, clock, publisher=world, on_tick=on_tick, command_thread=False)
    outcome = controller.run()
    assert outcome.ok, (outcome.reason, outcome.detail)
    order = phase_order(reports)
    assert Phase.GO_AROUND in order and order.count(Phase.APPROACH) == 2, order
    assert controller.state.recovery.attempts == 2 and controller.state.recovery.contact is not None
    assert max(switch_jumps(reports).values()) <= 0.05


def test_a_carrier_gone_quiet_on_the_approach_means_go_around_then_fallback(cfg):
    """The carrier's state stops during the approach: go around at once, then fall back after
    recovery.carrier_lost_s, to a point off its path, and hand over to Hold."""
    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(cfg.scenario.target, dtype=float),
                      recovery_velocity_ned_m_s=np.array([1.0, 0.0, 0.0]))
    reports: list[TickReport] = []
    cut = {"t": None}

    def on_tick(r: TickReport) -> None:
        reports.append(r)
        if r.phase is Phase.APPROACH and cut["t"] is None:
            cut["t"] = r.t_s
            world.carrier_until_s = r.t_s

    controller = MissionController(cfg, world, world.feed, clock, publisher=world, on_tick=on_tick, command_thread=False)
    outcome = controller.run()
    order = phase_order(reports)
    assert Phase.GO_AROUND in order and Phase.FALLBACK in order and order[-2:] == [Phase.HOLD, Phase.DONE], order
    went = next(r.t_s for r in reports if r.phase is Phase.GO_AROUND)
    assert went - cut["t"] <= 1.0  # within a second of the carrier going quiet (its state ages past 0.3 s)
    rec = controller.state.recovery
    assert "carrier" in rec.fallback_why and rec.contact is None
    assert outcome.ok  # a fallback is a safe end, not an abort


def test_the_battery_recalls_the_passenger_before_the_task_is_done(cfg):
    long_task = with_overrides(cfg, {"mission.at_target_s": 300.0})
    outcome, world, reports, controller = fly(long_task, recovery_velocity_ned_m_s=np.array([1.0, 0.0, 0.0]),
                                              battery_pct=100.0, drain_pct_s=0.6)
    assert outcome.ok, (outcome.reason, outcome.detail)
    rec = controller.state.recovery
    assert rec.why.startswith("battery") and rec.contact is not None
    left = world._battery(world.clock.now())
    assert left >= long_task.recovery.battery_reserve_pct - 5  # home with (about) the reserve


def test_recovery_phases_are_the_recovery_set():
    assert RECOVERY <= {p for p in Phase if p.flying and p.separated}


def test_the_summary_tells_how_the_recovery_went(cfg, tmp_path):
    from mission.record import FlightRecorder
    from mission.controller import mission_info

    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(cfg.scenario.target, dtype=float),
                      recovery_velocity_ned_m_s=np.array([1.0, 0.5, 0.0]))
    recorder = FlightRecorder(tmp_path, mission_info(cfg))
    controller = MissionController(cfg, world, world.feed, clock, publisher=world, recorder=recorder,
                                   command_thread=False)
    outcome = controller.run()
    s = outcome.summary
    assert s["docked_again"] is True and s["recovery_outcome"] == "docked"
    assert s["contact"]["attempts"] == 1 and s["contact"]["horizontal_error_m"] <= 0.10
    assert s["deck_violations"] == 0
    assert s["max_phase_switch_jump_m_s"] <= 0.05
    assert s["p1"] and s["p2"] and s["p3"]


class DoubtedFeed:
    """The fake world's feed, whose states the feed does not trust between ``from_s`` and
    ``until_s`` [s] (a relocalisation, a contested source: ``CarrierObs.untrusted``)."""

    def __init__(self, world: FakeWorld, clock: ManualClock) -> None:
        self.feed, self.clock = world.feed, clock
        self.from_s: float | None = None
        self.until_s = -1.0

    def latest(self):  # type: ignore[no-untyped-def]
        rx = self.feed.latest()
        now = self.clock.now()
        if rx is not None and self.from_s is not None and self.from_s <= now < self.until_s:
            return dataclasses.replace(rx, untrusted="settling: after a resync")
        return rx

    def __getattr__(self, name: str):  # type: ignore[no-untyped-def]
        return getattr(self.feed, name)


def test_an_untrusted_carrier_state_on_the_approach_means_go_around_and_no_contact_on_it(cfg):
    """The feed resyncs mid-approach (a relocalised or spoofed carrier): the approach is given up
    at once (go around, the reason named), nothing docks and PX4's home does not follow the
    carrier while the state is not trusted; once it is trusted again the passenger comes back
    and docks."""
    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(cfg.scenario.target, dtype=float),
                      recovery_velocity_ned_m_s=np.array([1.0, 0.0, 0.0]))
    feed = DoubtedFeed(world, clock)
    reports: list[TickReport] = []

    def on_tick(r: TickReport) -> None:
        reports.append(r)
        if r.phase is Phase.APPROACH and feed.from_s is None:
            feed.from_s, feed.until_s = r.t_s, r.t_s + 2.0

    controller = MissionController(cfg, world, feed, clock, publisher=world, on_tick=on_tick, command_thread=False)  # type: ignore[arg-type]
    outcome = controller.run()
    assert outcome.ok, (outcome.reason, outcome.detail)
    order = phase_order(reports)
    assert Phase.GO_AROUND in order and order.count(Phase.APPROACH) == 2 and Phase.DOCKED in order, order
    went = next(r for r in reports if r.phase is Phase.GO_AROUND)
    assert went.t_s - feed.from_s <= 0.05  # the very next tick
    doubted = [r for r in reports if feed.from_s < r.t_s < feed.until_s]  # from the tick after it began
    assert doubted and all(r.phase is not Phase.DOCKED and r.decision.home_ned_m is None for r in doubted)
    assert controller.state.recovery.contact is not None and controller.state.recovery.contact["time_s"] >= feed.until_s
