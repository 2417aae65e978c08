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


def test_a_go_around_names_why_the_carrier_state_is_unfit():
    """The go-around's reason is the real one: the carrier's liveliness token gone (its state may
    still be fresh), its state too old, no state, or a feed that does not trust it yet."""
    from mission.phases import CarrierObs, Observation
    from mission.phases.carrier_fitness import carrier_unfit

    def seen(**kw) -> Observation:
        c = CarrierObs(position_ned_m=np.zeros(3), velocity_ned_m_s=np.zeros(3), **{"age_s": 0.02, **kw})
        return Observation(t_s=10.0, vehicle=None, carrier=c)

    assert carrier_unfit(seen(), 0.3) is None
    assert carrier_unfit(seen(alive=False), 0.3) == \
        "carrier liveliness token gone (its last state 0.02 s old since the carrier measured it)"
    assert carrier_unfit(seen(age_s=0.45), 0.3) == \
        "carrier state 0.45 s old since the carrier measured it (recovery.carrier_max_age_s = 0.3)"
    # the age is the measurement's, good to the clock offset's bound: the worst case decides
    assert carrier_unfit(seen(age_s=0.25, age_bound_s=0.1), 0.3) == \
        "carrier state 0.25 +- 0.100 s old since the carrier measured it (recovery.carrier_max_age_s = 0.3)"
    assert carrier_unfit(seen(age_s=0.02, age_bound_s=None), 0.3) == \
        "the carrier's clock is not known (no round trip yet): its state's age is unknown"
    assert carrier_unfit(seen(age_s=-0.2, age_bound_s=0.01), 0.3) == (
        "carrier state stamped 0.20 s ahead of the carrier's clock (bound 0.010 s): its stamps and its round trips "
        "disagree")
    assert carrier_unfit(seen(untrusted="settling: after a resync"), 0.3) == \
        "carrier feed not trusted (settling: after a resync)"
    assert carrier_unfit(Observation(t_s=10.0, vehicle=None, carrier=None), 0.3) == "no carrier state"


def test_a_carrier_whose_token_goes_on_the_approach_is_named_in_the_go_around(cfg):
    """The carrier's token goes mid-approach while its last state is still 0.02 s old: the
    go-around says the token is gone, not that a 0.02 s old state is stale."""
    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(cfg.scenario.target, dtype=float),
                      recovery_velocity_ned_m_s=np.array([1.0, 0.0, 0.0]))
    reports: list[TickReport] = []

    def on_tick(r: TickReport) -> None:
        reports.append(r)
        if r.phase is Phase.APPROACH and world.carrier_until_s == float("inf"):
            world.carrier_until_s = r.t_s

    controller = MissionController(cfg, world, world.feed, clock, publisher=world, on_tick=on_tick, command_thread=False)
    controller.run()
    went = [e for r in reports for e in r.decision.events if e.startswith("go-around: ")]
    assert went and went[0].startswith("go-around: carrier liveliness token gone (its last state 0.0"), went


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
    from mission.record.recorder import FlightRecorder
    from mission.record.info import mission_info

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


def two_targets(cfg, second):
    first = list(cfg.scenario.target)
    return with_overrides(cfg, {"scenario.targets": [first, second]}), [first, second]


def test_two_targets_one_after_the_other(cfg):
    """Ride, separate, target 1, return, dock, then ride on: the carrier is still within b c + the
    leg margin of target 2, so it first drives out (TRANSIT), then carries the passenger under the
    law again, which separates at b c of target 2, and so on to the second dock."""
    two, targets = two_targets(cfg, [30.0, 5.0, -5.0])
    outcome, world, reports, controller = fly(two, targets=targets, recovery_velocity_ned_m_s=np.array([0.8, 0.0, 0.0]))
    assert outcome.ok, (outcome.reason, outcome.detail)
    order = phase_order(reports)
    leg2 = order.index(Phase.TRANSIT)
    assert order[leg2:] == [Phase.TRANSIT, Phase.RIDING, Phase.SEPARATED, Phase.NAVIGATING, Phase.ARRIVED,
                            Phase.RETURNING, Phase.HOLDOFF, Phase.APPROACH, Phase.DOCKED, Phase.HOME, Phase.HOLD,
                            Phase.DONE], order
    legs = controller.state.legs_done
    assert [leg["outcome"] for leg in legs] == ["done", "done"]
    bc = two.law.b * two.law.c
    for leg, target in zip(legs, targets):
        assert abs(norm(np.asarray(target) - np.asarray(leg["anchor_ned_m"])) - (bc - two.law.departure_margin_m)) < 1e-6
        assert leg["contact"]["horizontal_error_m"] <= 0.10
    assert max(switch_jumps(reports).values()) <= 0.05
    # the second leg began with the carrier at least b c + the margin from its target (Assumption 1)
    start2 = next(r for r in reports if r.phase is Phase.RIDING and r.t_s > legs[0]["end_s"])
    assert norm(np.asarray(targets[1]) - start2.decision.dock) >= bc + two.mission.leg_start_margin_m - 0.1


@pytest.fixture(scope="module")
def battery_for_one_leg(cfg, tmp_path_factory):
    """Two targets on a battery that drains 1 %/s from 100 %, recorded: one flight for the two
    tests that read it. (the config, the outcome, the world, the tick reports, the controller)"""
    from mission.record.info import mission_info
    from mission.record.recorder import FlightRecorder

    two, targets = two_targets(cfg, [30.0, 5.0, -5.0])
    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(targets[0], dtype=float), targets=targets,
                      recovery_velocity_ned_m_s=np.array([0.8, 0.0, 0.0]), battery_pct=100.0, drain_pct_s=1.0)
    reports: list[TickReport] = []
    controller = MissionController(two, world, world.feed, clock, publisher=world, on_tick=reports.append,
                                   recorder=FlightRecorder(tmp_path_factory.mktemp("battery"), mission_info(two)),
                                   command_thread=False)
    return two, controller.run(), world, reports, controller


def test_a_battery_too_small_for_the_second_leg_skips_it(battery_for_one_leg):
    two, outcome, world, reports, controller = battery_for_one_leg
    assert outcome.ok, (outcome.reason, outcome.detail)
    state = controller.state
    assert [leg["outcome"] for leg in state.legs_done] == ["done"]
    assert state.legs_skipped is not None and state.legs_skipped.startswith("battery")
    assert Phase.TRANSIT not in phase_order(reports)
    assert world._battery(world.clock.now()) >= two.recovery.battery_reserve_pct  # it never stranded itself


def test_the_summary_has_a_column_per_leg(cfg, tmp_path):
    from mission.record.info import mission_info
    from mission.record.recorder import FlightRecorder

    two, targets = two_targets(cfg, [30.0, 5.0, -5.0])
    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(targets[0], dtype=float), targets=targets,
                      recovery_velocity_ned_m_s=np.array([0.8, 0.0, 0.0]), carrier_accel_m_s2=1.0)
    controller = MissionController(two, world, world.feed, clock, publisher=world,
                                   recorder=FlightRecorder(tmp_path, mission_info(two)), command_thread=False)
    s = controller.run().summary
    legs = s["legs"]
    assert [leg["outcome"] for leg in legs] == ["done", "done"] and [leg["leg"] for leg in legs] == [0, 1]
    bc = two.law.b * two.law.c
    for leg, target in zip(legs, targets):
        assert leg["target_ned_m"] == target
        assert leg["p1"] and leg["p2"] and leg["p3"], leg
        assert abs(leg["carrier_target_distance_at_separation_m"] - bc) < 0.01
        assert leg["relative_input_jump_m_s"] <= 0.05
        assert leg["final_passenger_target_distance_m"] <= two.mission.arrival_radius_m
        assert leg["contact"]["horizontal_error_m"] <= 0.10 and leg["deck_violations"] == 0
        assert leg["separation_time_s"] > 0  # counted from the leg's own start of riding
    assert s["p1"] and s["p2"] and s["p3"]


def test_a_skipped_leg_is_reported_with_its_reason(battery_for_one_leg):
    _, outcome, *_ = battery_for_one_leg
    legs = outcome.summary["legs"]
    assert legs[0]["outcome"] == "done" and legs[1]["outcome"].startswith("skipped: battery")
    assert "p1" not in legs[1]


@pytest.mark.parametrize("rate_deg_s, steady", [(18.0, True), (19.5, True), (21.0, False), (25.0, False)])
def test_the_carriers_turn_is_measured_on_its_own_samples(cfg, rate_deg_s, steady):
    """A carrier turning steadily, sampled at 30 Hz and read by the 50 Hz tick (its sample's age
    between 0 and a period): its turn rate is measured between its samples' own times, so one
    just under recovery.carrier_max_turn_rate_deg_s (20) is steady and one just over is not
    (measured over tick times, 18 deg/s read as 21.4)."""
    import math

    from mission.model import mission_model
    from mission.phases import carrier_fitness
    from mission.phases.types import CarrierObs, Observation, RecoveryState

    r = mission_model(cfg).recovery
    rec, why = RecoveryState(started_s=0.0, why="task done"), []
    for k in range(200):
        t = k * 0.02
        sampled = math.floor(t * 30.0 + 1e-9) / 30.0
        heading = math.radians(rate_deg_s) * sampled
        v = 1.6 * np.array([math.cos(heading), math.sin(heading), 0.0])
        obs = Observation(t_s=t, vehicle=None, carrier=CarrierObs(v * sampled, v, age_s=t - sampled))
        rec = carrier_fitness.observe_carrier(rec, obs, r, t)
        why.append(carrier_fitness.carrier_unsteady(rec, obs, r))
    turning = [w for w in why if w is not None]
    assert (turning == []) is steady, turning[:1]
    if not steady:
        assert f"{rate_deg_s:.1f} deg/s" in turning[0]


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


def _fly_with(cfg, on_tick, **world_kwargs):
    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(cfg.scenario.target, dtype=float), **world_kwargs)
    reports: list[TickReport] = []

    def tick(r: TickReport) -> None:
        reports.append(r)
        on_tick(world, r)

    controller = MissionController(cfg, world, world.feed, clock, publisher=world, on_tick=tick, command_thread=False)
    return controller.run(), world, reports, controller


def test_out_of_line_on_the_descent_the_passenger_holds_its_height_and_docks_at_the_same_approach(cfg):
    """Pushed 0.25 m off the dock point (out of the 0.15 m contact radius, on the 0.5 m deck) just
    after it began its descent, the passenger holds its height over the deck, lines up again and
    docks at the same approach: no go-around."""
    pushed: dict = {"t": None, "out": []}

    def push(world: FakeWorld, r: TickReport) -> None:
        if pushed["t"] is None and "lined up over the deck: descending" in r.decision.events:
            pushed["t"] = r.t_s
            world.vehicle_ned_m = world.vehicle_ned_m + np.array([0.0, 0.25, 0.0])
        elif pushed["t"] is not None and r.phase is Phase.APPROACH and r.decision.dock is not None:
            e = world.vehicle_ned_m - r.decision.dock
            if float(norm(e[:2])) > cfg.recovery.contact_radius_m:
                pushed["out"].append(float(e[2]))  # its height error while out of line [m] NED

    outcome, world, reports, controller = _fly_with(cfg, push, recovery_velocity_ned_m_s=np.array([1.2, -0.9, 0.0]))
    assert outcome.ok, (outcome.reason, outcome.detail)
    assert pushed["t"] is not None and pushed["out"]
    order = phase_order(reports)
    assert Phase.GO_AROUND not in order and controller.state.recovery.attempts == 1, order
    assert controller.state.recovery.contact is not None
    # out of line, never down on the deck: always above the contact band
    assert max(pushed["out"]) < -cfg.recovery.contact_height_m, max(pushed["out"])


def test_the_holdoff_waits_for_the_carrier_to_move_when_told_to(cfg):
    """recovery.settle_carrier_speed_m_s: a carrier that stands at first (a rover that must turn
    onto its course) is not approached until it moves that fast."""
    slow = with_overrides(cfg, {"recovery.settle_carrier_speed_m_s": 1.0, "carrier.recovery_speed_m_s": 1.5})
    started: dict = {"t": None, "track": []}

    def start_late(world: FakeWorld, r: TickReport) -> None:
        if r.phase is Phase.HOLDOFF and started["t"] is None:
            started["t"] = r.t_s + 8.0  # it stands for 8 s after the passenger reached the holdoff point
        if started["t"] is not None and r.t_s >= started["t"]:
            world.recovery_velocity_ned_m_s = np.array([1.2, -0.9, 0.0])
        started["track"].append((r.t_s, r.phase, world.carrier_ned_m.copy()))

    outcome, world, reports, controller = _fly_with(slow, start_late, recovery_velocity_ned_m_s=np.zeros(3))
    assert outcome.ok, (outcome.reason, outcome.detail)
    track = started["track"]
    k = next(i for i, (_, phase, _) in enumerate(track) if phase is Phase.APPROACH)
    (t0, _, x0), (t1, _, x1) = track[k - 1], track[k]
    assert t1 > started["t"]
    assert float(norm((x1 - x0)[:2])) / (t1 - t0) >= 1.0 - 1e-6  # the carrier moved at least that fast
    assert controller.state.recovery.attempts == 1 and controller.state.recovery.contact is not None


def test_a_late_take_off_under_the_altitude_floor_is_led_by_the_reference(cfg):
    """PX4 leaves the ground a second or two after the reference has climbed to the dock point.
    Under the floor (safety.z_max_m) the floor's barrier must not take over the climb (it would
    send velocity only, a climb rate falling with the distance to the floor, under which PX4
    hovered just below it for 20 s): JOIN sends full setpoints there and the vehicle docks."""
    floor = cfg.safety.z_max_m
    assert floor is not None
    seen: dict = {"join": 0, "full": 0, "riding_s": None}

    def stuck_on_the_ground(world: FakeWorld, r: TickReport) -> None:
        if r.phase is Phase.JOIN:
            seen["t0"] = seen.get("t0", r.t_s)
            if r.t_s - seen["t0"] < 3.0:  # it stays on the ground for 3 s
                world.vehicle_ned_m = np.array([world.vehicle_ned_m[0], world.vehicle_ned_m[1], 0.0])
            # the reference has reached the dock point (1.5 m at 1 m/s), the vehicle is still down
            if r.t_s - seen["t0"] >= 2.0 and world.vehicle_ned_m[2] > floor and r.decision.setpoint is not None:
                seen["join"] += 1
                seen["full"] += r.decision.setpoint.position_ned_m is not None
        if r.phase is Phase.RIDING and seen["riding_s"] is None:
            seen["riding_s"] = r.t_s - seen["t0"]

    outcome, world, reports, controller = _fly_with(cfg, stuck_on_the_ground,
                                                    recovery_velocity_ned_m_s=np.array([1.2, -0.9, 0.0]))
    assert outcome.ok, (outcome.reason, outcome.detail)
    assert seen["join"] >= 40 and seen["full"] == seen["join"], seen
    assert seen["riding_s"] is not None and seen["riding_s"] < 6.0, seen


def test_a_contact_on_the_deck_is_confirmed_by_the_passengers_own_landed_state_only():
    """Seated after a contact, the contact counts once the vehicle itself reports ON_GROUND (its
    land detector), never on the carrier's word alone; the first such tick is kept."""
    from mission.phases import Observation, VehicleObs
    from mission.phases.recovery import _confirm_contact
    from mission.phases.types import RecoveryState

    def seen(t: float, on_ground: bool) -> Observation:
        v = VehicleObs(position_ned_m=np.zeros(3), velocity_ned_m_s=np.zeros(3), armed=True, mode="OFFBOARD",
                       heartbeat_age_s=0.0, on_ground=on_ground)
        return Observation(t_s=t, vehicle=v, carrier=None)

    rec = RecoveryState(started_s=0.0, why="task done", contact={"horizontal_error_m": 0.07})
    assert _confirm_contact(rec, seen(40.0, False)) is rec  # in the air (or PX4 does not say): not confirmed
    confirmed = _confirm_contact(rec, seen(41.5, True))
    assert confirmed is not None and confirmed.contact == {
        "horizontal_error_m": 0.07, "confirmed_s": 41.5, "confirmed_by": "landed on the deck (EXTENDED_SYS_STATE ON_GROUND)"}
    assert _confirm_contact(confirmed, seen(43.0, True)) is confirmed
    no_contact = RecoveryState(started_s=0.0, why="task done")
    assert _confirm_contact(no_contact, seen(41.5, True)) is no_contact


def test_transit_names_its_wait_for_the_carrier():
    """A carrier parked within b c + the leg margin of the next target: TRANSIT rides on and, every
    ``TRANSIT_REPORT_S``, names the wait with the distances it compares (pure, synthetic
    observations), so a wait that lasts until the mission's timeout says why in the events."""
    from mission.controller import mission_model
    from mission.phases import CarrierObs, MissionState, Observation, VehicleObs
    from mission.phases.recovery import TRANSIT_REPORT_S, transit
    from mission.phases.types import RecoveryState, dock_point

    m = mission_model(load_config(CONFIGS / "cycle.toml"))
    target = np.asarray(m.tick.target, dtype=float)
    short = m.leg_start_m - 3.0  # the dock point stands 3 m inside where the leg starts
    carrier = CarrierObs(target - np.array([short, 0.0, 0.0]) - np.asarray(m.dock_offset_ned_m), np.zeros(3), age_s=0.0)
    t0 = 100.0
    dock = dock_point(Observation(t_s=t0, vehicle=None, carrier=carrier), m)  # type: ignore[arg-type]
    assert abs(norm(target - dock) - short) < 1e-9
    state = MissionState(phase=Phase.TRANSIT, since_s=t0, x_ref=dock.copy(), u_ref=np.zeros(3), u_cmd=np.zeros(3),
                         recovery=RecoveryState(started_s=0.0, why="task done", attempts=1, carrier_seen_s=t0), leg=1)
    events: list[tuple[float, str]] = []
    for k in range(int(40.0 / m.dt_s)):
        t = t0 + k * m.dt_s
        vehicle = VehicleObs(dock.copy(), np.zeros(3), True, "OFFBOARD", heartbeat_age_s=0.0, on_ground=False)
        state, dec = transit(state, Observation(t_s=t, vehicle=vehicle, carrier=carrier), m)
        state = dataclasses.replace(state, tick_s=t)
        events += [(t - t0, e) for e in dec.events]
        assert state.phase is Phase.TRANSIT
    assert [round(when, 6) for when, _ in events] == [TRANSIT_REPORT_S, 2 * TRANSIT_REPORT_S], events
    assert f"the dock point is {short:.2f} m from the target (the leg starts at {m.leg_start_m:.2f} m" in events[0][1]
