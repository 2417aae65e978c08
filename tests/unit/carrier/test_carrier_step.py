"""The carrier's one step (mission/carrier/step.py), pure: the guard's parameters are built in one
place and set by the backend's declared properties, a vehicle that brakes itself is sent a stop
at once while the built-in robot ramps down, Remark 1 keeps the command of the separation
instant, the recovery course keeps its start through a pause, and the recovery simulation's
carrier (sim/batch/recovery.py) commands what the controller's loop on the built-in robot
commands, step for step (over real Zenoh: tests/integration/carrier/test_carrier_step_agrees.py)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mission.carrier.backends import OwnState
from mission.carrier.backends.sim import SimRobot
from mission.carrier.modes import CarrierMode, PassengerView
from mission.carrier.step import REAL_DELAY_S, CarrierStepper, carrier_model, guard_params, tracking_params
from mission.carrier.tracking import Tracked, autopilot_speed_m_s, speed_loop_corrected
from mission.config.schema import Config, from_dict
from mission.phases.phase import Phase
from mission.time.clock import ManualClock
from sim.batch.recovery import KinematicCarrier, configured, sim_backend

TARGET = [20.0, 15.0, -4.0]
DT = 1.0 / 30.0
ACCEL = 1.0  # [m/s^2] safety.carrier_max_accel_m_s2 of _cfg
RADIUS = 8.0 - 0.5  # [m] b c - carrier.p3_margin_m


def _cfg(carrier_mode: str = "stop", **carrier: object) -> Config:
    return from_dict({
        "scenario": {"carrier_start": [0.0, 0.0, 0.0], "target": TARGET, "carrier_mode": carrier_mode},
        "safety": {"carrier_max_accel_m_s2": ACCEL, "carrier_max_speed_m_s": 2.5},
        "carrier": {"rate_hz": 30.0, "max_speed_m_s": 3.0, **carrier},
    })


def _view(phase: str) -> PassengerView:
    p = Phase(phase)
    return PassengerView(p, p.separated)


def _step(stepper: CarrierStepper, robot: SimRobot, clock: ManualClock, phase: str | None) -> np.ndarray:
    """One tick of the controller's loop on the built-in robot (without its bus): advance, the
    mode, the own state, the command held; the command's velocity [m/s]."""
    clock.advance(DT)
    robot.advance(DT)
    stepper.update_mode(PassengerView(None) if phase is None else _view(phase))
    cmd = stepper.decide(robot.own_state(), DT, 0.0, clock.now()).tracked
    robot.command(cmd)
    return np.array(cmd.velocity_ned_m_s, dtype=float)


def test_the_guard_s_parameters_are_built_once_and_the_backend_kind_sets_the_delay() -> None:
    sim, px4 = guard_params(_cfg()), guard_params(_cfg(backend="mavlink"))
    assert sim.delay_s == 0.0 and px4.delay_s == REAL_DELAY_S  # the built-in robot obeys at once
    assert guard_params(_cfg(backend="mavlink", brake_delay_s=0.1)).delay_s == 0.1  # a stated delay wins
    assert sim.radius_m == pytest.approx(RADIUS) and sim.brake_decel_m_s2 == ACCEL and sim.period_s == DT
    assert CarrierStepper(_cfg(backend="mavlink"), True).guard == px4


def test_the_simulation_s_carrier_steps_with_the_sim_backend_s_parameters() -> None:
    """A configuration for a PX4 rover simulated: the robot simulated is the built-in one (no
    response delay, braking by the law's limit), whatever carrier.backend says."""
    cfg = _cfg(backend="mavlink")
    carrier = KinematicCarrier(cfg, configured())
    assert sim_backend(cfg).carrier.backend == "sim" and cfg.carrier.backend == "mavlink"
    assert carrier.stepper.guard == guard_params(sim_backend(cfg)) != guard_params(cfg)
    assert not carrier.stepper.brakes_itself and not SimRobot.brakes_itself
    assert carrier.model.carrier_safety.max_speed_m_s == carrier_model(cfg).carrier_safety.max_speed_m_s == 2.5


@pytest.mark.parametrize("brakes_itself", [True, False])
def test_a_vehicle_that_brakes_itself_is_sent_a_stop_at_once_the_built_in_robot_ramps_down(brakes_itself: bool) -> None:
    clock = ManualClock()
    stepper, robot = CarrierStepper(_cfg(), brakes_itself), SimRobot(_cfg(), clock)
    v = [_step(stepper, robot, clock, "RIDING") for _ in range(60)]
    assert stepper.mode is CarrierMode.APPROACHING and np.linalg.norm(v[-1]) == pytest.approx(2.0 * ACCEL, rel=1e-6)
    after = _step(stepper, robot, clock, "NAVIGATING")
    assert stepper.mode is CarrierMode.SEPARATED and stepper.stopping()
    if brakes_itself:
        assert not after.any() and not stepper.velocity_m_s.any()
    else:
        assert np.linalg.norm(after) == pytest.approx(np.linalg.norm(v[-1]) - ACCEL * DT, rel=1e-6)


def test_remark1_keeps_the_command_of_the_separation_instant() -> None:
    clock = ManualClock()
    cfg = _cfg(carrier_mode="remark1")
    stepper, robot = CarrierStepper(cfg, False), SimRobot(cfg, clock)
    v = [_step(stepper, robot, clock, "RIDING") for _ in range(30)]
    after = [_step(stepper, robot, clock, "NAVIGATING") for _ in range(30)]
    assert stepper.mode is CarrierMode.SEPARATED and not stepper.stopping()
    for u in after:
        np.testing.assert_allclose(u, v[-1], atol=1e-12)


def test_the_recovery_course_keeps_its_start_through_a_pause_and_a_new_recovery_starts_its_own() -> None:
    """1 s east, then the steady course north: paused 0.5 s into the course for 1 s, it comes
    back to the steady course (its clock ran on); a recovery after a fall-back starts east again."""
    stepper = CarrierStepper(_cfg(recovery_course=[[90.0, 1.0, 1.0]], recovery_heading_deg=0.0,
                                  recovery_speed_m_s=1.0), False)
    x = np.zeros(3)
    stepper.mode = CarrierMode.SEPARATED
    stepper.update_mode(_view("RETURNING"))
    assert stepper.mode is CarrierMode.RECOVERING
    np.testing.assert_allclose(stepper.course_velocity(x, 10.0), [0.0, 1.0, 0.0], atol=1e-12)  # its start: 10 s
    stepper.update_mode(PassengerView(Phase.APPROACH, True, "its liveliness token is gone"))
    assert stepper.mode is CarrierMode.PAUSED and stepper.course_velocity(x, 10.5) is None
    stepper.update_mode(_view("APPROACH"))
    np.testing.assert_allclose(stepper.course_velocity(x, 11.5), [1.0, 0.0, 0.0], atol=1e-12)  # 1.5 s in: steady
    stepper.update_mode(_view("FALLBACK"))
    assert stepper.mode is CarrierMode.SEPARATED
    stepper.update_mode(_view("RETURNING"))
    np.testing.assert_allclose(stepper.course_velocity(x, 20.0), [0.0, 1.0, 0.0], atol=1e-12)  # a new start


def test_the_simulation_s_carrier_commands_what_the_controller_s_loop_commands() -> None:
    """The same phases heard, step for step: the same command and the same motion. Gentle start,
    a scripted course turn and a steady course into the guard's circle all in play."""
    towards = math.degrees(math.atan2(TARGET[1], TARGET[0]))
    cfg = _cfg(start_accel_m_s2=0.5, recovery_course=[[towards + 90.0, 1.0, 2.01]], recovery_heading_deg=towards,
               recovery_speed_m_s=1.5)
    clock = ManualClock()
    stepper, robot = CarrierStepper(cfg, SimRobot.brakes_itself), SimRobot(cfg, clock)
    carrier = KinematicCarrier(cfg, configured())
    carrier.step(None, None)  # its first step, at 0 (the controller's loop: nothing to do before the first tick)
    script = ["RIDING"] * 120 + ["NAVIGATING"] * 60 + ["RETURNING"] * 10 + ["APPROACH"] * 400 + ["HOME"] * 90 \
        + ["RIDING"] * 30
    closest = math.inf
    for phase in script:
        u = _step(stepper, robot, clock, phase)
        cmd = carrier.step(Phase(phase), None)
        assert carrier.mode is stepper.mode
        np.testing.assert_allclose(cmd.velocity_ned_m_s, u, atol=1e-9)
        np.testing.assert_allclose(carrier.position, robot.position_m, atol=1e-9)
        closest = min(closest, float(np.linalg.norm(np.asarray(TARGET) - robot.position_m)))
    assert stepper.mode is CarrierMode.APPROACHING
    assert RADIUS - 1e-9 <= closest < RADIUS + 0.1  # the steady course ran into the guard's circle


def test_the_steady_course_away_from_the_target_turns_clear_of_the_other_targets_keep_outs() -> None:
    """Target 1 lies on the way back from target 0: the recovery course away from target 0 would
    run into target 1's keep-out, where its barrier row turned the carrier (up to 20 deg/s in the
    team's Monte-Carlo, under a passenger on its approach, which went round). The default heading
    turns as little as clears it (at the course's speed the row never wakes): the carrier drives
    one straight course, no closer to target 0 on the way."""
    t0, t1 = [20.0, 0.0, -4.0], [-10.0, 3.0, -4.0]
    cfg = from_dict({
        "scenario": {"carrier_start": [0.0, 0.0, 0.0], "targets": [t0, t1], "carrier_mode": "stop"},
        "safety": {"carrier_max_accel_m_s2": ACCEL, "carrier_max_speed_m_s": 2.0},
        "carrier": {"rate_hz": 30.0, "max_speed_m_s": 2.0, "recovery_speed_m_s": 1.5},
        "mission": {"final_action": "return"},
    })
    clock = ManualClock()
    stepper, robot = CarrierStepper(cfg, False), SimRobot(cfg, clock)
    for _ in range(int(40 / DT)):  # approach target 0 until the separation, then brake
        phase = "RIDING" if np.linalg.norm(np.subtract(t0, robot.own_state().position_ned_m)) > 8.0 else "NAVIGATING"
        _step(stepper, robot, clock, phase)
    start = robot.own_state().position_ned_m.copy()
    away = math.degrees(math.atan2(start[1] - t0[1], start[0] - t0[0]))
    keep = stepper.legs.models[0].other_keep_outs
    assert keep is not None and len(keep) == 1
    r1 = float(keep.radii[0]) + stepper.model.carrier_safety.margin_m
    rel = np.subtract(t1[:2], start[:2])
    along = np.array([math.cos(math.radians(away)), math.sin(math.radians(away))])
    assert abs(rel[0] * along[1] - rel[1] * along[0]) < r1  # straight away would cut into target 1's keep-out
    headings, closest_t0, closest_t1 = [], math.inf, math.inf
    for _ in range(int(40 / DT)):
        u = _step(stepper, robot, clock, "RETURNING")
        x = robot.own_state().position_ned_m
        closest_t0 = min(closest_t0, float(np.linalg.norm(np.subtract(t0[:2], x[:2]))))
        closest_t1 = min(closest_t1, float(np.linalg.norm(np.subtract(t1[:2], x[:2]))))
        if np.linalg.norm(u[:2]) > 0.5:
            headings.append(math.degrees(math.atan2(u[1], u[0])))
    assert stepper.mode is CarrierMode.RECOVERING
    turns = np.abs((np.diff(headings) + 180.0) % 360.0 - 180.0) / DT
    assert float(turns.max()) < 0.5  # [deg/s] one straight course
    assert 0.0 < abs((headings[-1] - away + 180.0) % 360.0 - 180.0) <= 90.0  # turned off away, never towards target 0
    assert closest_t1 >= r1  # it passed target 1's keep-out
    assert closest_t0 >= float(np.linalg.norm(np.subtract(t0[:2], start[:2]))) - 1e-6  # no closer to target 0


def test_a_target_behind_another_s_keep_out_is_reached_round_it() -> None:
    """Target 0 lies straight behind target 1's keep-out, as seen from the carrier's start: the
    barrier row alone takes away all of the law's command at the keep-out's edge (an equilibrium
    of its quadratic program: the team Monte-Carlo's carrier stood there 850 s). The carrier veers
    round it to the right and brings its rider within b c of target 0, never inside the keep-out."""
    t0, t1 = [40.0, 0.0, -4.0], [15.0, 0.0, -4.0]
    cfg = from_dict({
        "scenario": {"carrier_start": [0.0, 0.0, 0.0], "targets": [t0, t1], "carrier_mode": "stop"},
        "safety": {"carrier_max_accel_m_s2": ACCEL, "carrier_max_speed_m_s": 2.0},
        "carrier": {"rate_hz": 30.0, "max_speed_m_s": 2.0},
        "mission": {"final_action": "return"},
    })
    clock = ManualClock()
    stepper, robot = CarrierStepper(cfg, False), SimRobot(cfg, clock)
    keep = stepper.legs.models[0].other_keep_outs
    assert keep is not None and len(keep) == 1
    least, reached = math.inf, None
    for k in range(int(90 / DT)):
        _step(stepper, robot, clock, "RIDING")
        x = robot.own_state().position_ned_m
        least = min(least, float(np.linalg.norm(np.subtract(t1[:2], x[:2]))))
        if np.linalg.norm(np.subtract(t0, x)) <= 8.0:
            reached = k * DT
            break
    assert reached is not None and reached < 30.0, reached  # [s] (22.4 s; the straight way, were it free: 16 s)
    assert least >= float(keep.radii[0])
    assert stepper.mode is CarrierMode.APPROACHING


@pytest.mark.parametrize("turn_deg", [0.0, 106.0, 180.0])
def test_an_ackermann_carrier_turning_from_rest_is_not_braked_by_its_own_lead(turn_deg: float) -> None:
    """The PX4 cycle's start settings (gentle start 0.25 m/s^2, lead 0.3 m/s) on an Ackermann
    carrier that stands facing ``turn_deg`` away from its target's bearing (leg 2 on PX4: 106 deg).
    The lead caps the forward speed asked at the measured one plus 0.3 m/s; capped before the
    tracking law, the planar command was then scaled by max(cos e, 0.3), the carrier was asked
    less than it did, and it crawled at ~0.14 m/s for the whole turn (facing away: forever), the
    crawl at which PX4's SIH rover sticks and leaps. The speed asked grows at most at the law's
    acceleration limit; while it turns it is the tracking law's floor, 0.3 x 1.2 m/s."""
    bearing = math.atan2(TARGET[1], TARGET[0])
    cfg = from_dict({
        "scenario": {"carrier_start": [0.0, 0.0, 0.0], "target": TARGET, "carrier_mode": "stop"},
        "safety": {"carrier_max_accel_m_s2": ACCEL, "carrier_max_speed_m_s": 2.0},
        "carrier": {"rate_hz": 30.0, "max_speed_m_s": 1.2, "kinematics": "ackermann", "wheelbase_m": 0.321,
                    "max_steer_rad": 0.5236, "min_speed_fraction": 0.3, "start_accel_m_s2": 0.25,
                    "start_lead_m_s": 0.3, "start_yaw_rad": bearing + math.radians(turn_deg)},
    })
    clock = ManualClock()
    stepper, robot = CarrierStepper(cfg, False), SimRobot(cfg, clock)
    asked, error_deg = [], []
    for _ in range(int(6.0 / DT)):
        _step(stepper, robot, clock, "RIDING")
        asked.append(robot.speed_m_s)
        error_deg.append(abs(math.degrees(math.remainder(robot.yaw_rad - bearing, 2 * math.pi))))
    assert stepper.mode is CarrierMode.APPROACHING
    speed, error, t = np.array(asked), np.array(error_deg), np.arange(1, len(asked) + 1) * DT
    assert np.diff(speed).max() <= ACCEL * DT + 1e-9  # never faster than the law's own ramp
    turning = (t > 1.5) & (error > 60.0)  # past the gentle start (0.25 m/s^2 to 0.36 m/s), not yet lined up
    if turn_deg > 60.0:
        assert turning.any() and speed[turning].min() >= 0.3 * 1.2 - 1e-6  # old: 0.12-0.14 m/s
    assert error[-1] < 5.0 and speed[-1] == pytest.approx(1.2, abs=0.01)  # lined up and at the law's speed (old, 180: 0.14)


def _px4_rover_cfg(min_moving_speed_m_s: float, targets: list[list[float]] | None = None,
                   start_yaw_rad: float | None = None, start_motion_tau_s: float = 0.0,
                   speed_loop_correction: float = 0.0, floor_from_m_s: float = 0.0) -> Config:
    """The PX4 cycle's rover settings (gentle start 0.25 m/s^2, lead 0.3 m/s, Ackermann)."""
    return from_dict({
        "scenario": {"carrier_start": [0.0, 0.0, 0.0], "carrier_mode": "stop",
                     **({"targets": targets} if targets else {"target": TARGET})},
        "safety": {"carrier_max_accel_m_s2": ACCEL, "carrier_max_speed_m_s": 2.0},
        **({"mission": {"final_action": "return"}} if targets else {}),
        "carrier": {"rate_hz": 30.0, "max_speed_m_s": 1.2, "kinematics": "ackermann", "wheelbase_m": 0.321,
                    "max_steer_rad": 0.5236, "min_speed_fraction": 0.3, "start_accel_m_s2": 0.25,
                    "start_lead_m_s": 0.3, "min_moving_speed_m_s": min_moving_speed_m_s,
                    "start_yaw_rad": start_yaw_rad, "recovery_speed_m_s": 1.2,
                    "start_motion_tau_s": start_motion_tau_s, "speed_loop_correction": speed_loop_correction,
                    "floor_from_m_s": floor_from_m_s},
    })


@pytest.mark.parametrize("floor", [0.0, 0.8])
def test_a_rover_whose_estimate_wanders_sideways_is_never_asked_a_crawl(floor: float) -> None:
    """PX4's SIH rover at rest after a drive: its EKF says 0.6 m/s sideways and a forward speed
    that flips +-0.2 m/s while it stands. The gentle start and the lead key on that forward speed;
    they asked 0.1-0.8 m/s in turn, inside the band its speed loop cannot resolve, and it swung 0 to
    0.9 m/s under the riding passenger. With carrier.min_moving_speed_m_s the speed asked is the
    law's own (1 m/s^2) up to the floor, and never below it after."""
    cfg = _px4_rover_cfg(floor)
    stepper = CarrierStepper(cfg, True)
    bearing = math.atan2(TARGET[1], TARGET[0])
    side = np.array([-math.sin(bearing), math.cos(bearing), 0.0]) * 0.6
    ahead = np.array([math.cos(bearing), math.sin(bearing), 0.0])
    stepper.update_mode(_view("RIDING"))
    asked = []
    for k in range(int(3.0 / DT)):
        t = (k + 1) * DT
        forward = 0.2 if (k // 5) % 2 else -0.2  # its sign flips every 5 ticks, the rover stands
        state = OwnState(t, np.zeros(3), side + forward * ahead, bearing)
        asked.append(stepper.decide(state, DT, 0.0, t).tracked.speed_m_s)
    speed = np.array(asked)
    assert stepper.mode is CarrierMode.APPROACHING
    later = speed[int(1.0 / DT):]  # [s] 1 s on: the law asks 1 m/s and more
    if floor:
        assert later.min() >= 0.8 - 1e-9 and speed[int(0.5 / DT)] == pytest.approx(0.5, abs=0.04)
        assert np.diff(speed).max() <= ACCEL * DT + 1e-9  # never faster than the law's own ramp
    else:
        assert later.max() < 0.8  # the crawl the floor removes


@pytest.mark.parametrize("floor", [0.0, 0.8])
def test_a_rover_repositioning_turns_to_face_the_next_target_before_it_stands(floor: float) -> None:
    """Leg 2 on PX4: the rover docked the passenger driving its recovery course, away from target
    1 and ~150 deg off target 2's bearing, and stood so; leg 2's ride then began with a turn from
    rest. With carrier.min_moving_speed_m_s it turns towards target 2 at that speed while the
    passenger is in TRANSIT and stands facing it, beyond the leg-start distance."""
    t0, t1 = [15.0, 0.0, -5.0], [-25.0, -10.0, -4.0]
    cfg = _px4_rover_cfg(floor, targets=[t0, t1], start_yaw_rad=math.radians(20.0))
    clock = ManualClock()
    stepper, robot = CarrierStepper(cfg, False), SimRobot(cfg, clock)
    stepper.mode = CarrierMode.RECOVERING  # driving its course (20 deg) when the passenger docks
    for _ in range(int(2.0 / DT)):
        _step(stepper, robot, clock, "DOCKED")
    for _ in range(int(20.0 / DT)):
        clock.advance(DT)
        robot.advance(DT)
        stepper.update_mode(PassengerView(Phase.TRANSIT, leg=1))
        robot.command(stepper.decide(robot.own_state(), DT, 0.0, clock.now()).tracked)
    state = robot.own_state()
    x = state.position_ned_m
    bearing = math.atan2(t1[1] - x[1], t1[0] - x[0])
    error_deg = abs(math.degrees(math.remainder(bearing - float(state.yaw_rad), 2 * math.pi)))
    assert stepper.mode is CarrierMode.REPOSITIONING and robot.speed_m_s == pytest.approx(0.0, abs=1e-9)
    dock = x + np.asarray(cfg.mission.dock_offset_ned_m)
    assert float(np.linalg.norm(np.subtract(t1, dock))) >= stepper.legs.start_m  # the leg can start
    if floor:
        assert error_deg <= 12.0  # facing target 2 (a 10 deg tolerance and the braking's last turn)
    else:
        assert error_deg > 90.0  # the old stand: facing away (109 deg)


@pytest.mark.parametrize("floor", [0.0, 0.8])
def test_a_rover_that_never_crawls_stands_a_second_once_stopped(floor: float) -> None:
    """Asked to drive the tick after it was told to stop (leg 2's ride began as its turn towards
    target 2 ended), PX4's SIH rover leapt to 1.9 m/s: its speed loop had not been reset by a
    held rest point. With carrier.min_moving_speed_m_s it stands RESTART_S (1 s) first, then
    starts from rest at the law's ramp."""
    cfg = _px4_rover_cfg(floor)
    stepper = CarrierStepper(cfg, True)
    bearing = math.atan2(TARGET[1], TARGET[0])
    still = OwnState(0.0, np.zeros(3), np.zeros(3), bearing)
    now = 0.0
    for phase, seconds in (("RIDING", 3.0), ("NAVIGATING", 0.5)):
        for _ in range(round(seconds / DT)):
            now += DT
            stepper.update_mode(_view(phase))
            stepper.decide(dataclasses.replace(still, t_s=now), DT, 0.0, now)
    stopped_at = now  # told to stop 0.5 s ago
    asked = []
    for k in range(int(2.0 / DT)):
        t = stopped_at + (k + 1) * DT
        stepper.update_mode(_view("RETURNING"))
        asked.append(stepper.decide(dataclasses.replace(still, t_s=t), DT, 0.0, t).tracked.speed_m_s)
    assert stepper.mode is CarrierMode.RECOVERING
    speed, t = np.array(asked), np.arange(1, len(asked) + 1) * DT
    if floor:
        assert speed[t < 0.5 - 1e-6].max() == 0.0 and speed[-1] > 0.2  # stood 1 s in all, then drove
        assert np.diff(speed).max() <= ACCEL * DT + 1e-9  # from rest, at the law's ramp
    else:
        assert speed[0] > 0.0


@pytest.mark.parametrize("floor", [0.0, 0.8])
def test_a_leg_s_ride_begins_from_a_stand_though_repositioning_never_asked_a_stop(floor: float) -> None:
    """Leg 2 on PX4: the rover's repositioning braked out of its turn (the law's command ramping
    0.8 -> 0 at 1 m/s^2) and the passenger began the ride when the published speed fell below
    0.1 m/s, while 0.03 m/s was still asked: no stop was ever asked, so the stand after one
    (RESTART_S) never ran; PX4 held no rest point, the rover rolled back, then leapt, and the
    passenger trailed 0.316 m. With carrier.min_moving_speed_m_s a ride begins from a stand:
    RESTART_S (1 s) of stop from the ride's first tick, then the gentle start from rest."""
    t0, t1 = [15.0, 0.0, -5.0], [-25.0, -10.0, -4.0]
    stepper = CarrierStepper(_px4_rover_cfg(floor, targets=[t0, t1]), True)
    x = np.array([-5.0, 0.0, 0.0])  # beyond leg 2's start, facing target 2
    bearing = math.atan2(t1[1] - x[1], t1[0] - x[0])
    ahead = np.array([math.cos(bearing), math.sin(bearing), 0.0])
    stepper.mode = CarrierMode.REPOSITIONING  # its turn towards target 2 just ended, 0.8 m/s asked
    stepper.update_mode(PassengerView(Phase.TRANSIT, leg=1))
    stepper.velocity_m_s = 0.8 * ahead
    now, asked = 0.0, [0.8]
    for _ in range(round(0.7 / DT)):  # braking: the speed asked ramps down, never to zero
        now += DT
        x = x + ahead * asked[-1] * DT
        state = OwnState(now, x.copy(), ahead * asked[-1], bearing)
        asked.append(stepper.decide(state, DT, 0.0, now).tracked.speed_m_s)
        stepper.update_mode(PassengerView(Phase.TRANSIT, leg=1))
    assert stepper.mode is CarrierMode.REPOSITIONING and 0.0 < asked[-1] < 0.15  # still asked, no stop
    ride = []
    for _ in range(round(2.0 / DT)):  # the ride: the rover has come to rest (and stays so)
        now += DT
        stepper.update_mode(PassengerView(Phase.RIDING, leg=1))
        ride.append(stepper.decide(OwnState(now, x.copy(), np.zeros(3), bearing), DT, 0.0, now).tracked.speed_m_s)
    assert stepper.mode is CarrierMode.APPROACHING
    speed, t = np.array(ride), np.arange(1, len(ride) + 1) * DT
    if floor:
        assert speed[t < 1.0 - 1e-6].max() == 0.0  # old: 0.11 m/s asked at once, 0.34 at 1 s; no rest point held
        assert 0.0 < speed[-1] <= 0.25 * 1.0 + 0.01  # then the gentle start from rest
    else:
        assert speed[0] > 0.0


def test_from_a_clean_stand_the_gentle_start_stays() -> None:
    """Leg 1 on PX4 (its estimate at rest clean): asked the floor's 0.8 m/s at once the SIH rover
    leapt to 0.55 m/s in 0.13 s and the passenger trailed 0.39 m; the gentle start (0.25 m/s^2)
    breaks it free lower. The floor waits until it moves or its estimate errs sideways."""
    stepper = CarrierStepper(_px4_rover_cfg(0.8), True)
    bearing = math.atan2(TARGET[1], TARGET[0])
    stepper.update_mode(_view("RIDING"))
    asked = [stepper.decide(OwnState((k + 1) * DT, np.zeros(3), np.zeros(3), bearing), DT, 0.0, (k + 1) * DT)
             .tracked.speed_m_s for k in range(int(2.0 / DT))]
    assert max(asked) == pytest.approx(0.25 * 2.0, abs=0.01)  # 2 s at 0.25 m/s^2


def test_a_floor_that_sets_in_mid_start_grows_at_the_law_s_ramp() -> None:
    """Leg 1 on PX4: the gentle start asked 0.32 m/s when the EKF's sideways velocity reached
    0.19 m/s; the floor then asked 0.80 m/s the next tick, the rover leapt to 1.1 m/s and the
    passenger trailed 0.37 m. The floor grows from the speed asked at the law's acceleration."""
    stepper = CarrierStepper(_px4_rover_cfg(0.8), True)
    bearing = math.atan2(TARGET[1], TARGET[0])
    side = np.array([-math.sin(bearing), math.cos(bearing), 0.0])
    stepper.update_mode(_view("RIDING"))
    asked = []
    for k in range(int(3.0 / DT)):
        t = (k + 1) * DT
        v = side * (0.0 if t < 1.2 else 0.2)  # a clean stand, then its estimate errs sideways
        asked.append(stepper.decide(OwnState(t, np.zeros(3), v, bearing), DT, 0.0, t).tracked.speed_m_s)
    speed = np.array(asked)
    assert np.diff(speed).max() <= ACCEL * DT + 1e-9  # old: 0.30 -> 0.80 in one tick
    assert speed[-1] >= 0.8 - 1e-9  # the floor reached


@pytest.mark.parametrize("floor", [0.0, 0.8])
def test_the_lead_never_takes_back_speed_asked_when_the_estimate_turns_sideways(floor: float) -> None:
    """Leg 2 on PX4, mid-ride at 1.2 m/s: the SIH rover's EKF put 0.9-1.1 m/s of its velocity
    sideways, and PX4's speed loop, which reads the velocity's size, slowed it (forward 1.0 ->
    0.5 m/s). The lead, keyed on the forward speed, cut the speed asked to it plus 0.3 m/s, down to
    the floor; PX4 slowed the rover to a stop and it leapt off again, the passenger 0.53 m off the
    dock. The lead holds the speed asked back while it starts; it takes none back."""
    stepper = CarrierStepper(_px4_rover_cfg(floor), True)
    bearing = math.atan2(TARGET[1], TARGET[0])
    ahead = np.array([math.cos(bearing), math.sin(bearing), 0.0])
    side = np.array([-math.sin(bearing), math.cos(bearing), 0.0])
    stepper.update_mode(_view("RIDING"))
    asked = [0.0]
    for k in range(int(6.0 / DT)):
        t = (k + 1) * DT
        if t < 3.0:  # it follows what it was asked, a tick late
            v = ahead * asked[-1]
        else:  # its estimate turns sideways and PX4 slows it
            v = ahead * max(1.0 - (t - 3.0) / 1.5 * 0.5, 0.5) + side * 0.95
        asked.append(stepper.decide(OwnState(t, np.zeros(3), v, bearing), DT, 0.0, t).tracked.speed_m_s)
    speed, times = np.array(asked[1:]), np.arange(1, len(asked)) * DT
    assert speed[times < 3.0].max() == pytest.approx(1.2, abs=1e-6)  # the law's speed, reached
    assert speed[times >= 3.0].min() >= 1.2 - 1e-6  # old: 0.8 (the forward speed plus 0.3; the floor)


@pytest.mark.parametrize("tau_s", [0.0, 0.3])
def test_a_rover_standing_still_under_an_erring_estimate_starts_gently(tau_s: float) -> None:
    """Leg 2 on PX4: the SIH rover braked out of its turn and stood (its position's rate -0.05 to
    +0.03 m/s) while its EKF said -0.25 m/s forward and 0.2-0.3 m/s sideways. Read as moving, the
    speed asked ramped at the law's 1 m/s^2, the rover stuck until asked 0.7-0.8 m/s, leapt to
    1.3 m/s in 0.5 s, and the riding passenger trailed 0.30-0.35 m. With
    carrier.start_motion_tau_s it is judged by its velocity made consistent with its position: it
    stands, and the gentle start (0.25 m/s^2) asks for speed; once its position moves, the floor."""
    stepper = CarrierStepper(_px4_rover_cfg(0.8, start_motion_tau_s=tau_s), True)
    bearing = math.atan2(TARGET[1], TARGET[0])
    ahead = np.array([math.cos(bearing), math.sin(bearing), 0.0])
    side = np.array([-math.sin(bearing), math.cos(bearing), 0.0])
    erring = -0.25 * ahead + 0.25 * side  # [m/s] its EKF's velocity while it stands
    now = 0.0
    for _ in range(round(1.5 / DT)):  # it stands, told to stop, while the passenger is in transit
        now += DT
        stepper.update_mode(_view("TRANSIT"))
        stepper.decide(OwnState(now, np.zeros(3), erring, bearing), DT, 0.0, now)
    asked, x = [], np.zeros(3)
    for k in range(round(4.0 / DT)):
        now += DT
        free = k * DT >= 1.6  # 1.6 s into the ride it breaks free at 0.4 m/s, its estimate now right
        x = x + (0.4 * ahead * DT if free else 0.0)
        stepper.update_mode(_view("RIDING"))
        state = OwnState(now, x.copy(), 0.4 * ahead if free else erring, bearing)
        asked.append(stepper.decide(state, DT, 0.0, now).tracked.speed_m_s)
    speed, t = np.array(asked), np.arange(1, len(asked) + 1) * DT
    assert stepper.mode is CarrierMode.APPROACHING
    standing = t <= 1.6
    if tau_s:
        assert speed[standing].max() <= 0.25 * 1.6 + 0.01  # the gentle start (old: the law's ramp to 0.8)
        assert speed[-1] >= 0.8 - 1e-9  # once it moves, the floor and the law's ramp
    else:
        assert speed[standing].max() >= 0.8 - 1e-9  # the old ramp: 0.8 asked of a rover that stands
    assert np.diff(speed).max() <= ACCEL * DT + 1e-9


def test_the_carrier_steers_on_its_fixes_smoothed_by_its_inertial_velocity() -> None:
    """carrier.fix_smoothing_tau_s: fixes 2 m off the truth (a bias) with 0.3 m of white noise at 10 Hz,
    the robot driving at 1.5 m/s: the position steered on keeps the bias and sheds the noise
    (0.1 m from truth + bias on average after 6 s, the raw fixes 0.37 m), its velocity the
    inertial one; without an inertial state (a real backend's own state is its EKF already), or at 0,
    the state itself."""
    rng = np.random.default_rng(4)
    bias = np.array([2.0, -1.0, 0.0])
    velocity = np.array([1.5, 0.0, 0.0])
    stepper = CarrierStepper(_cfg(fix_smoothing_tau_s=2.0), False)
    errors, raw_errors = [], []
    for k in range(100):
        t = 0.1 * k
        truth = OwnState(t, velocity * t, velocity.copy(), 0.0)
        fix = OwnState(t, truth.position_ned_m + bias + 0.3 * rng.standard_normal(3) * [1, 1, 0],
                       velocity + 0.2 * rng.standard_normal(3) * [1, 1, 0], 0.0, inertial=truth)
        steered = stepper.navigated(fix)
        assert stepper.navigated(fix).position_ned_m.tolist() == steered.position_ned_m.tolist()  # once per fix
        np.testing.assert_allclose(steered.velocity_ned_m_s, velocity)
        if t >= 6.0:
            errors.append(float(np.linalg.norm(steered.position_ned_m - truth.position_ned_m - bias)))
            raw_errors.append(float(np.linalg.norm(fix.position_ned_m - truth.position_ned_m - bias)))
    assert np.mean(errors) < 0.1 and max(errors) < 0.2 and np.mean(raw_errors) > 0.3, (errors, raw_errors)
    raw = OwnState(1.0, np.array([3.0, 4.0, 0.0]), np.array([1.0, 0.0, 0.0]), 0.0)
    assert stepper.navigated(raw) is raw
    off = CarrierStepper(_cfg(), False)
    assert off.navigated(fix) is fix


def _px4_throttle(asked_m_s: float, measured_m_s: float) -> float:
    """PX4's rover throttle without its integral (RoverControl::speedControl): the feed-forward
    asked / RO_MAX_THR_SPEED plus RO_SPEED_P times the error, for the bench's 4 m/s and 0.5."""
    return asked_m_s / 4.0 + 0.5 * (asked_m_s - measured_m_s)


SPEED_LOOP_K = 0.5 / (0.5 + 1.0 / 4.0)  # RO_SPEED_P / (RO_SPEED_P + 1 / RO_MAX_THR_SPEED)


def test_px4_s_speed_loop_measures_its_estimate_s_size_signed_by_its_forward_part() -> None:
    """AckermannVelControl: the EKF velocity's size, signed by its forward part, 0 below RO_SPEED_TH."""
    yaw = 0.3
    ahead, side = np.array([math.cos(yaw), math.sin(yaw)]), np.array([-math.sin(yaw), math.cos(yaw)])
    assert autopilot_speed_m_s(-0.23 * ahead - 0.18 * side, yaw) == pytest.approx(-math.hypot(0.23, 0.18))
    assert autopilot_speed_m_s(0.05 * ahead + 0.30 * side, yaw) == pytest.approx(math.hypot(0.05, 0.30))
    assert autopilot_speed_m_s(0.06 * ahead + 0.07 * side, yaw) == 0.0  # 0.092 m/s: under 0.1, read as 0


@pytest.mark.parametrize(("ekf_forward", "ekf_side", "moving"), [
    (-0.23, -0.18, 0.0),  # a7's stand: its EKF read -0.29 m/s, the rover stood
    (+0.10, +0.30, 0.10),  # creeping at 0.1 m/s, the EKF's sideways error flips the reading to +0.32
    (+0.15, -0.35, 0.0),  # a4's stand: read +0.38 m/s forward while it stood
    (+1.30, +0.40, 1.45),  # mid-ride: EKF velocity 0.1 m/s behind its position, 0.4 sideways
])
def test_a_rover_s_speed_loop_is_asked_so_that_its_throttle_sees_its_consistent_speed(
        ekf_forward: float, ekf_side: float, moving: float) -> None:
    """With carrier.speed_loop_correction = RO_SPEED_P / (RO_SPEED_P + 1 / RO_MAX_THR_SPEED), the
    speed asked of PX4, through its speed loop's reading of the EKF velocity, gives the throttle
    (feed-forward and proportional term) that the speed wanted gives against the speed the carrier
    really makes (its velocity consistent with its position): a7 and a9's leg 2 began with the
    rover read at -0.29 m/s while it stood (a push at the first ask), and broke free, stalled on
    the flip to +0.3 and leapt. The motion wanted is kept; the setpoint keeps its bearing."""
    yaw = 0.7
    ahead, side = np.array([math.cos(yaw), math.sin(yaw)]), np.array([-math.sin(yaw), math.cos(yaw)])
    p = tracking_params(_cfg(kinematics="ackermann", wheelbase_m=0.321, max_steer_rad=0.5236,
                             speed_loop_correction=SPEED_LOOP_K))
    ekf, motion = ekf_forward * ahead + ekf_side * side, moving * ahead
    measured = autopilot_speed_m_s(ekf, yaw)
    for wanted in (0.3, 0.6, 1.2):
        cmd = Tracked(wanted, 0.1, yaw, wanted * ahead, wanted * ahead)
        out = speed_loop_corrected(cmd, yaw, ekf, motion, p)
        assert _px4_throttle(out.speed_m_s, measured) == pytest.approx(_px4_throttle(wanted, moving), abs=1e-9)
        assert np.linalg.norm(out.setpoint_ned_m_s) == pytest.approx(out.speed_m_s)
        assert out.setpoint_ned_m_s @ ahead == pytest.approx(out.speed_m_s)  # the bearing kept
        assert np.array_equal(out.velocity_ned_m_s, cmd.velocity_ned_m_s)  # the motion wanted kept
        off = speed_loop_corrected(cmd, yaw, ekf, motion, dataclasses.replace(p, speed_loop_correction=0.0))
        assert off is cmd
    # uncorrected, the stand's -0.29 m/s reading pushes at a tenth of the throttle that breaks it free
    if ekf_forward < 0:
        assert _px4_throttle(0.01, measured) - _px4_throttle(0.01, moving) == pytest.approx(0.146, abs=0.001)


def test_the_speed_loop_correction_never_turns_a_stop_into_a_drive_nor_a_drive_into_a_stop() -> None:
    """A stop stays a stop; a speed asked that the correction would take below 0.01 m/s is asked
    0.01 m/s (the speed loop's reading -0.9 m/s of a rover that stands); the error is at most 1 m/s."""
    p = dataclasses.replace(tracking_params(_cfg(kinematics="ackermann")), speed_loop_correction=SPEED_LOOP_K)
    stop = Tracked(0.0, 0.0, 0.0, np.zeros(2), np.zeros(2))
    assert speed_loop_corrected(stop, 0.0, np.array([-0.9, 0.0]), np.zeros(2), p) is stop
    slow = Tracked(0.2, 0.0, 0.0, np.array([0.2, 0.0]), np.array([0.2, 0.0]))
    assert speed_loop_corrected(slow, 0.0, np.array([-0.9, 0.0]), np.zeros(2), p).speed_m_s == pytest.approx(0.01)
    assert speed_loop_corrected(slow, 0.0, np.array([3.0, 0.0]), np.zeros(2), p).speed_m_s == pytest.approx(
        0.2 + SPEED_LOOP_K * 1.0)
    assert speed_loop_corrected(slow, None, np.array([-0.9, 0.0]), np.zeros(2), p) is slow
    # under a P3 guard's cut it may lower the speed asked, never raise it (its position read it rolling back)
    assert speed_loop_corrected(slow, 0.0, np.zeros(2), np.array([-0.3, 0.0]), p, guarded=True) is not slow
    assert speed_loop_corrected(slow, 0.0, np.zeros(2), np.array([-0.3, 0.0]), p, guarded=True).speed_m_s == 0.2
    assert speed_loop_corrected(slow, 0.0, np.zeros(2), np.array([-0.3, 0.0]), p).speed_m_s == pytest.approx(
        0.2 + SPEED_LOOP_K * 0.3)
    assert speed_loop_corrected(slow, 0.0, np.array([-0.15, 0.0]), np.zeros(2), p, guarded=True).speed_m_s == (
        pytest.approx(0.2 - SPEED_LOOP_K * 0.15))


def test_the_carrier_step_asks_a_px4_rover_s_speed_loop_the_corrected_speed() -> None:
    """Wired in the step: leg 2's start on a stand read at -0.29 m/s (position still), the speed
    asked of the rover is the gentle start's less 2/3 of 0.29 m/s (at least 0.01 m/s); the same
    step without the correction asks the gentle start's."""
    def run(k: float) -> list[float]:
        stepper = CarrierStepper(_px4_rover_cfg(0.8, start_motion_tau_s=0.3, speed_loop_correction=k), True)
        bearing = math.atan2(TARGET[1], TARGET[0])
        ahead = np.array([math.cos(bearing), math.sin(bearing), 0.0])
        side = np.array([-math.sin(bearing), math.cos(bearing), 0.0])
        erring = -0.23 * ahead - 0.18 * side
        now, asked = 0.0, []
        for phase, seconds in (("TRANSIT", 1.5), ("RIDING", 2.5)):
            for _ in range(round(seconds / DT)):
                now += DT
                stepper.update_mode(_view(phase))
                asked.append(stepper.decide(OwnState(now, np.zeros(3), erring, bearing), DT, 0.0, now).tracked.speed_m_s)
        return asked
    plain, corrected = np.array(run(0.0)), np.array(run(SPEED_LOOP_K))
    driving = plain > 0
    assert driving.sum() > 20 and plain.max() > 0.3  # the gentle start asks for speed
    want = np.maximum(plain[driving] - SPEED_LOOP_K * math.hypot(0.23, 0.18), np.minimum(plain[driving], 0.01))
    assert corrected[driving] == pytest.approx(want, abs=0.01)  # the consistent speed: ~0 (its position still)
    assert np.array_equal(corrected[~driving], plain[~driving])  # the stops stay


@pytest.mark.parametrize("floor_from", [0.0, 0.8])
def test_a_rover_crawling_off_a_stand_is_led_not_pulled_up_to_the_floor(floor_from: float) -> None:
    """Off a stand the SIH rover broke free and crawled at 0.15-0.3 m/s for 0.5 s while the floor's
    ramp asked it 0.8 m/s (it counted as moving at 0.15), then leapt to 1.1-1.5 m/s under the riding
    passenger. With carrier.floor_from_m_s = 0.8 the floor sets in only once it moves at 0.8 m/s:
    crawling at 0.2 m/s it is asked at most 0.2 + the lead (0.3); once at 0.9 m/s, it is asked no
    less though it reads 0.5 m/s again (the floor, then the lead never taking back speed asked).
    0: the floor's ramp from 0.15 m/s, as before."""
    stepper = CarrierStepper(_px4_rover_cfg(0.8, start_motion_tau_s=0.3, floor_from_m_s=floor_from), True)
    bearing = math.atan2(TARGET[1], TARGET[0])
    ahead = np.array([math.cos(bearing), math.sin(bearing), 0.0])
    now, x = 0.0, np.zeros(3)
    for _ in range(round(1.5 / DT)):  # it stands, told to stop, while the passenger is in transit
        now += DT
        stepper.update_mode(_view("TRANSIT"))
        stepper.decide(OwnState(now, x.copy(), np.zeros(3), bearing), DT, 0.0, now)
    asked, speeds = [], []
    for k in range(round(5.0 / DT)):
        now += DT
        speed = 0.0 if k * DT < 2.0 else 0.2 if k * DT < 3.5 else 0.9 if k * DT < 4.0 else 0.5  # [m/s] what it does
        x = x + speed * ahead * DT
        stepper.update_mode(_view("RIDING"))
        asked.append(stepper.decide(OwnState(now, x.copy(), speed * ahead, bearing), DT, 0.0, now).tracked.speed_m_s)
        speeds.append(speed)
    asked_a, t = np.array(asked), np.arange(1, len(asked) + 1) * DT
    crawl = (t >= 2.5) & (t < 3.5)  # crawling for a while (its motion filter caught up)
    if floor_from:
        assert asked_a[crawl].max() <= 0.2 + 0.3 + 0.02  # the lead (old: the floor's ramp to 0.8)
        assert asked_a[t >= 4.1].min() >= 0.8 - 1e-9  # it moved at the floor's speed: no less asked
    else:
        assert asked_a[crawl].max() >= 0.8 - 1e-9  # the old ramp: 0.8 asked of a rover that crawls at 0.2
