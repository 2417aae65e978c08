"""PX4's home kept at the carrier, and PX4's offboard-loss action for a recovery, on the fake world
(no sockets, manual clock): what the controller sends, when, and what it puts back."""
from __future__ import annotations

import numpy as np
import pytest

from mission.config.schema import load_config, with_overrides
from mission.controller import MissionController, TickReport
from mission.mavlink.commander import HOME_MIN_MOVE_M, HOME_PERIOD_S, home_update_due
from mission.core.law import norm
from mission.phases import Phase
from mission.time.clock import ManualClock
from tests.conftest import CONFIGS
from tests.support.fake_vehicle import FakeWorld


def fly(cfg, **world_kwargs):
    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(cfg.scenario.target, dtype=float), **world_kwargs)
    reports: list[TickReport] = []
    controller = MissionController(cfg, world, world.feed, clock, publisher=world, on_tick=reports.append,
                                   command_thread=False)
    return controller.run(), world, reports, controller


def test_home_update_due_first_then_at_most_once_a_period_and_only_when_moved():
    here = np.array([1.0, 2.0, 0.0])
    assert home_update_due(None, 0.0, here)
    last = (10.0, here)
    moved = here + [HOME_MIN_MOVE_M, 0.0, 0.0]
    assert not home_update_due(last, 10.0 + HOME_PERIOD_S - 0.01, moved)  # too soon
    assert home_update_due(last, 10.0 + HOME_PERIOD_S, moved)
    assert not home_update_due(last, 100.0, here + [0.3, 0.3, 0.0])  # 0.42 m: not meaningful


@pytest.fixture(scope="module")
def hold_mission():
    return fly(load_config(CONFIGS / "demo.toml"))


def test_home_follows_the_carrier_while_flying_only(hold_mission):
    outcome, world, reports, controller = hold_mission
    assert outcome.ok
    assert world.homes, "no home sent"
    flying = [r.t_s for r in reports if r.phase.flying]
    assert world.homes[0][0] >= flying[0] - 1e-9 and world.homes[-1][0] <= flying[-1] + 1e-9
    times = np.array([t for t, _ in world.homes])
    assert np.all(np.diff(times) >= HOME_PERIOD_S - 1e-9)
    homes = np.array([h for _, h in world.homes])
    assert np.all(np.linalg.norm(np.diff(homes, axis=0), axis=-1) >= HOME_MIN_MOVE_M - 1e-9)
    # each is where the carrier was then (its state is the fake's truth, its age 0)
    by_t = {r.t_s: r.decision.home_ned_m for r in reports}
    for t, home in world.homes:
        assert np.allclose(home, by_t[t])
    assert norm(homes[-1] - world.carrier_ned_m) < HOME_MIN_MOVE_M + 1e-9  # it follows to the carrier's stop
    assert controller._counters()["home"]["accepted"] == len(world.homes)
    assert world.param_sets == []  # a mission that does not return leaves PX4's failsafe alone


@pytest.fixture(scope="module")
def recovery_cfg():
    return with_overrides(load_config(CONFIGS / "demo.toml"), {"mission.final_action": "return", "mission.at_target_s": 2.0,
                                                               "mission.max_duration_s": 600.0})


def test_a_recovery_sets_offboard_loss_to_return_while_it_flies_and_puts_it_back(recovery_cfg):
    outcome, world, reports, controller = fly(recovery_cfg, recovery_velocity_ned_m_s=np.array([1.0, 0.0, 0.0]))
    assert outcome.ok, (outcome.reason, outcome.detail)
    assert [(name, value) for _, name, value in world.param_sets] == [("COM_OBL_RC_ACT", 3.0), ("COM_OBL_RC_ACT", 0.0)]
    t_set, t_restored = world.param_sets[0][0], world.param_sets[1][0]
    first_flying = next(r.t_s for r in reports if r.phase.flying)
    assert t_set <= first_flying and t_restored >= reports[-1].t_s  # before the flight, after the last tick
    assert controller.px4_params["COM_OBL_RC_ACT"] == {"was": 0.0, "set": 3.0, "restored": 0.0}
    assert controller.px4_params["BAT_CRIT_THR"] == 0.07
    docked = [t for t, h in world.homes if any(r.t_s == t and r.phase == Phase.RETURNING for r in reports)]
    assert docked, "the home moves while the passenger returns"


def test_a_recovery_keeps_the_vehicles_own_offboard_loss_action_when_asked(recovery_cfg):
    cfg = with_overrides(recovery_cfg, {"recovery.offboard_loss_return": False})
    outcome, world, _, controller = fly(cfg)
    assert outcome.ok and world.param_sets == [] and "COM_OBL_RC_ACT" not in controller.px4_params


def test_a_vehicle_already_at_return_is_left_as_it_is(recovery_cfg):
    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(recovery_cfg.scenario.target, dtype=float))
    world.params["COM_OBL_RC_ACT"] = 3.0
    controller = MissionController(recovery_cfg, world, world.feed, clock, publisher=world, command_thread=False)
    assert controller.run().ok and world.param_sets == []
    assert controller.px4_params["COM_OBL_RC_ACT"] == {"was": 3.0, "set": 3.0}


def test_a_home_moved_by_someone_else_is_found_and_set_again_and_a_changed_parameter_restored():
    from mission.mavlink.commander import HomeKeeper
    from mission.mavlink.commander import ParamKeeper, home_moved
    from mission.time.clock import ManualClock

    sent = [(10.0, np.array([1.0, 2.0, 0.0]))]
    assert home_moved(sent, [1.3, 2.0, 0.0], 12.0) is None  # our own, read back
    assert home_moved(sent, [24.0, 18.0, 0.0], 10.1) is None  # a report from before ours took
    assert home_moved(sent, [24.0, 18.0, 0.0], 12.0) == pytest.approx(np.hypot(23.0, 16.0))

    class Vehicle:
        def __init__(self):
            self.home = None
            self.params = {"COM_OBL_RC_ACT": 3.0}
            self.homes = []

        @property
        def state(self):
            from types import SimpleNamespace
            return SimpleNamespace(home_ned_m=self.home, home_rx_s=clock.now())

        def set_home(self, home):
            self.homes.append(np.array(home))
            self.home = np.array(home)
            return 0

        def get_param(self, name):
            return self.params[name]

        def set_param(self, name, value):
            self.params[name] = value
            return value

    clock = ManualClock(0.0)
    vehicle = Vehicle()
    params = ParamKeeper(vehicle.get_param, vehicle.set_param)
    params.keep("COM_OBL_RC_ACT", 3.0)
    keeper = HomeKeeper(vehicle, clock, threaded=False, params=params)
    keeper.offer(np.array([1.0, 2.0, 0.0]))
    clock.advance(1.0)
    keeper.check()
    assert keeper.counters["moved"] == 0 and params.counters["read"] == 1
    vehicle.home = np.array([24.0, 18.0, 0.0])  # a rogue's DO_SET_HOME
    vehicle.params["COM_OBL_RC_ACT"] = 7.0  # and its offboard-loss action: Disarm
    keeper.check()
    assert keeper.counters["moved"] == 1 and keeper.counters["restored"] == 1
    assert vehicle.home.tolist() == [1.0, 2.0, 0.0]
    assert vehicle.params["COM_OBL_RC_ACT"] == 3.0 and params.moves == [{"name": "COM_OBL_RC_ACT", "found": 7.0, "ours": 3.0,
                                                                          "restored": 3.0}]
    clock.advance(1.0)
    vehicle.home = np.array([24.0, 18.0, 0.0])  # moved again just before the mission ends
    keeper.close()  # the last word is ours
    assert vehicle.home.tolist() == [1.0, 2.0, 0.0]
