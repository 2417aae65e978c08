"""The carrier of a team (mission/carrier/team.py), pure, against scripted passengers: one
passenger's team commands exactly what the single-passenger stepper commands; a team of two is
served in the mission's order, hands over only to a passenger on board for the next target, never
skips a target whose passenger is away, waits for every passenger to join, and keeps out of every
target's keep-out."""
from __future__ import annotations

import numpy as np

from mission.carrier.backends.sim import SimRobot
from mission.carrier.modes import CarrierMode, PassengerView
from mission.carrier.step import CarrierStepper
from mission.carrier.team import TeamCarrier
from mission.config.passenger import carrier_config
from mission.config.schema import load_config
from mission.phases.phase import Phase
from mission.time.clock import ManualClock
from tests.conftest import CONFIGS

DT = 1.0 / 30.0  # carrier.rate_hz of cycle.toml and team.toml


def _view(phase: Phase, leg: int = 0) -> PassengerView:
    return PassengerView(phase, phase.separated, leg=leg)


def _dist(robot: SimRobot, target, dock) -> float:
    return float(np.linalg.norm(np.asarray(target) - (robot.own_state().position_ned_m + np.asarray(dock))))


def test_one_passenger_s_team_commands_what_the_single_stepper_does() -> None:
    """configs/cycle.toml (two targets, recovery): one scripted passenger drives both carriers;
    every command is the same, bit for bit."""
    cfg = load_config(CONFIGS / "cycle.toml")
    clock_a, clock_b = ManualClock(), ManualClock()
    single, robot_a = CarrierStepper(cfg, SimRobot.brakes_itself), SimRobot(cfg, clock_a)
    team, robot_b = TeamCarrier(cfg, SimRobot.brakes_itself), SimRobot(cfg, clock_b)
    targets, dock = cfg.scenario.legs(), cfg.mission.dock_offset_ned_m
    script = [(Phase.JOIN, 0)] * 20
    leg, phase, since = 0, Phase.RIDING, 0
    seen = set()
    for k in range(4000):
        if k < len(script):
            phase, leg = script[k]
            phase = Phase.RIDING if k == len(script) - 1 else phase
        elif phase is Phase.RIDING and _dist(robot_a, targets[leg], dock) <= 8.0:
            phase, since = Phase.SEPARATED, k
        elif phase is Phase.SEPARATED and k - since > 60:
            phase, since = Phase.RETURNING, k
        elif phase is Phase.RETURNING and k - since > 300:
            phase = Phase.HOME if leg == len(targets) - 1 else Phase.TRANSIT
            leg = leg if phase is Phase.HOME else leg + 1
        elif phase is Phase.TRANSIT and _dist(robot_a, targets[leg], dock) >= 9.5:
            phase = Phase.RIDING
        view = _view(phase, leg)
        commands = []
        for stepper, robot, clock in ((single, robot_a, clock_a), (team, robot_b, clock_b)):
            clock.advance(DT)
            robot.advance(DT)
            if isinstance(stepper, TeamCarrier):
                stepper.update_mode([view])
            else:
                stepper.update_mode(view)
            cmd = stepper.decide(robot.own_state(), DT, 0.0, clock.now()).tracked
            robot.command(cmd)
            commands.append(np.asarray(cmd.velocity_ned_m_s, dtype=float))
        assert np.array_equal(commands[0], commands[1]), k
        assert single.mode is team.mode
        seen.add(single.mode)
    assert {CarrierMode.APPROACHING, CarrierMode.SEPARATED, CarrierMode.RECOVERING, CarrierMode.REPOSITIONING,
            CarrierMode.PARKED} <= seen  # the script went through the whole cycle, both legs
    assert team.hand_overs == [] and team.done == {0, 1}


class _Team:
    """configs/team.toml's carrier on the built-in robot, alpha (targets 0, 2) and bravo (target 1)
    scripted: each rides until the carrier announces its target and the dock point is within b c."""

    def __init__(self) -> None:
        cfg = load_config(CONFIGS / "team.toml")
        own, self.docks = carrier_config(cfg)
        self.clock = ManualClock()
        self.robot = SimRobot(own, self.clock)
        self.carrier = TeamCarrier(cfg, SimRobot.brakes_itself)
        self.targets = own.scenario.legs()
        self.radius = self.carrier.stepper.guard.radius_m
        self.closest = [np.inf] * len(self.targets)
        self.announced: list[int] = []
        self.separated_at: list[tuple[str, int, int]] = []  # (who, own target, announced)

    def step(self, views: list[PassengerView]) -> None:
        self.clock.advance(DT)
        self.robot.advance(DT)
        self.carrier.update_mode(views)
        cmd = self.carrier.decide(self.robot.own_state(), DT, 0.0, self.clock.now()).tracked
        self.robot.command(cmd)
        x = self.robot.own_state().position_ned_m
        for k, t in enumerate(self.targets):
            self.closest[k] = min(self.closest[k], float(np.linalg.norm(np.asarray(t) - x)))
        if not self.announced or self.announced[-1] != self.carrier.heading_for():
            self.announced.append(self.carrier.heading_for())

    def ready(self, own_target: int) -> bool:
        """The turn gate and the latch: announced, and the dock point within b c."""
        dock = self.docks[own_target]
        return self.carrier.heading_for() == own_target and _dist(self.robot, self.targets[own_target], dock) <= 8.0


def test_a_team_is_served_in_order_and_the_carrier_never_skips_an_away_passenger() -> None:
    team = _Team()
    alpha, bravo = _view(Phase.JOIN), _view(Phase.JOIN)
    for _ in range(30):  # alpha rides, bravo still joins: the carrier waits for bravo
        team.step([_view(Phase.RIDING), bravo])
    assert team.carrier.mode is CarrierMode.WAITING and np.allclose(team.robot.own_state().position_ned_m, 0.0)
    alpha = bravo = _view(Phase.RIDING)
    for _ in range(3000):
        if alpha.phase is Phase.RIDING and team.ready(0):
            alpha = _view(Phase.NAVIGATING)
            team.separated_at.append(("alpha", 0, team.carrier.heading_for()))
        if bravo.phase is Phase.RIDING and team.ready(1):
            bravo = _view(Phase.NAVIGATING)
            team.separated_at.append(("bravo", 1, team.carrier.heading_for()))
        team.step([alpha, bravo])
    # alpha left at target 0, the carrier took bravo to target 1; alpha (target 2 next) is away:
    # the carrier stays with bravo's leg and stops, it does not head for target 2
    assert team.separated_at == [("alpha", 0, 0), ("bravo", 1, 1)]
    assert team.carrier.hand_overs == [(0, 1)]
    assert team.announced == [0, 1]
    assert team.carrier.mode is CarrierMode.SEPARATED and team.carrier.done == {0, 1}
    assert float(np.linalg.norm(team.robot.own_state().velocity_ned_m_s)) == 0.0
    # alpha comes home and rides on for target 2 (its leg 1): the carrier hands over to it
    for _ in range(100):
        team.step([_view(Phase.TRANSIT, leg=1), _view(Phase.RETURNING)])
    assert team.carrier.hand_overs == [(0, 1), (1, 0)] and team.announced == [0, 1, 2]
    assert team.carrier.mode in (CarrierMode.REPOSITIONING, CarrierMode.APPROACHING)
    alpha = _view(Phase.RIDING, leg=1)
    for _ in range(3000):
        if alpha.phase is Phase.RIDING and team.ready(2):
            alpha = _view(Phase.NAVIGATING, leg=1)
            team.separated_at.append(("alpha", 2, team.carrier.heading_for()))
        team.step([alpha, _view(Phase.RETURNING)])
    assert team.separated_at[-1] == ("alpha", 2, 2)
    assert team.carrier.done == {0, 1, 2}
    # P3 for every target: the carrier never inside any target's guard circle (b c - p3 margin)
    assert min(c - team.radius for c in team.closest) >= -1e-6, team.closest
    assert team.closest[1] < team.radius + 0.5  # it did drive up to the guard of target 1 (the test can fail)


def test_no_hand_over_to_a_passenger_on_another_leg() -> None:
    """bravo flies target 1 but alpha, the owner of target 0, has not left: the carrier keeps
    heading for target 0 whatever bravo says."""
    team = _Team()
    for _ in range(300):
        team.step([_view(Phase.RIDING), _view(Phase.RIDING)])
    assert team.carrier.heading_for() == 0 and team.carrier.hand_overs == []
    assert team.carrier.mode is CarrierMode.APPROACHING
