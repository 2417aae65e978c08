"""The P3 guard's model of a robot that moves along its heading (pure): its stopping path, a turn
in progress included, and the turn away from a target it faces, never enter the guard circle."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mission.carrier.guard import GuardParams, P3Guard
from mission.carrier.stopping import allowed_path_m, closing_m, stop_closing_m, turn_away_m
from mission.core.geodesy import wrap_pi

R_GUARD = 7.5


def _closest_on_path(phi: float, path: float, radius: float, steer: list[float], rho: float = 8.0) -> float:
    """Distance closed [m] on a point ``rho`` away by a path of length ``path`` whose curvature
    is ``steer[i] / radius`` on each of its equal pieces (|steer| <= 1), starting ``phi`` off it."""
    x, y, psi = 0.0, 0.0, phi  # the point at (rho, 0); heading psi from the x axis
    n = 2000
    ds = path / n
    best = 0.0
    for i in range(n):
        k = steer[i * len(steer) // n] / radius
        x, y, psi = x + ds * math.cos(psi), y + ds * math.sin(psi), psi + ds * k
        best = max(best, rho - math.hypot(rho - x, y))
    return best


@pytest.mark.parametrize("phi_deg", [0.0, 20.0, 60.0, 90.0, 135.0, 180.0])
@pytest.mark.parametrize("path", [0.3, 1.0, 3.0])
def test_the_closing_bound_holds_whatever_the_robot_steers(phi_deg: float, path: float) -> None:
    rng = np.random.default_rng(int(phi_deg * 10 + path * 100))
    phi, radius = math.radians(phi_deg), 0.6
    bound = closing_m(phi, path, radius)
    steers = [[-1.0], [1.0], [0.0]] + [list(rng.uniform(-1, 1, 8)) for _ in range(30)]
    worst = max(_closest_on_path(phi, path, radius, s) for s in steers)
    assert worst <= bound + 1e-3, (worst, bound)
    # ... and it is near tight: turning towards the point at the tightest turn, then straight at it,
    # closes about that much (the bound leaves out the line of sight's turn: 10 % after a U-turn)
    towards = _closest_on_path(phi, path, radius, [-1.0 if (i + 0.5) / 1000 * path < radius * phi else 0.0
                                                   for i in range(1000)])
    assert towards >= bound - 0.12 * max(bound, 1.0) or bound == 0.0, (towards, bound)


def test_the_closing_bound_of_a_robot_that_turns_on_the_spot_is_its_path() -> None:
    assert closing_m(math.pi, 2.0, 0.0) == 2.0
    assert closing_m(0.0, 2.0, 0.6) == pytest.approx(2.0)
    assert closing_m(math.pi, 0.5, 0.6) == 0.0  # facing away, a short path cannot face it yet


def test_a_turn_away_closes_its_radius_from_facing_the_target_and_nothing_from_beside_it() -> None:
    assert turn_away_m(0.0, 0.8) == pytest.approx(0.8)
    assert turn_away_m(0.5 * math.pi, 0.8) == pytest.approx(0.0)
    assert turn_away_m(2.0, 0.8) == 0.0
    # the arc itself: turning away at 0.8 m from facing the point closes 0.8 m (its quarter circle)
    assert _closest_on_path(0.0, 0.8 * math.pi, 0.8, [1.0], rho=50.0) == pytest.approx(0.8, abs=0.01)


def test_the_allowed_path_is_the_longest_that_stays_in_the_room() -> None:
    for phi, clear, radius, reserve in ((0.0, 2.0, 0.6, 0.0), (1.0, 1.0, 0.6, 0.5), (2.5, 0.4, 0.6, 0.3),
                                        (0.0, 0.5, 0.0, 0.2)):
        s = allowed_path_m(phi, clear, radius, reserve)
        assert stop_closing_m(phi, s, radius, reserve) <= clear + 1e-9
        assert stop_closing_m(phi, s + 1e-3, radius, reserve) > clear
    assert allowed_path_m(0.0, 0.5, 0.6, 0.6) == 0.0  # no room to turn away: it may not move
    assert allowed_path_m(0.0, -0.1, 0.6, 0.0) == 0.0


class _Rover:
    """A car in the plane: forward speed v >= 0 [m/s] and heading psi [rad]; it obeys each command
    (speed, bearing) ``lag`` steps late, reaches the speed at ``accel`` / brakes at ``decel``
    [m/s^2], and steers to the bearing at a yaw rate of at most ``v / radius``."""

    def __init__(self, x: np.ndarray, psi: float, v: float, radius: float, decel: float, lag: int,
                 accel: float = 3.0) -> None:
        self.x, self.psi, self.v = np.array(x, dtype=float), psi, v
        self.radius, self.decel, self.accel = radius, decel, accel
        self.queue: list[tuple[float, float]] = [(v, psi)] * lag

    def step(self, dt: float, speed: float, bearing: float) -> None:
        self.queue.append((speed, bearing))
        u, beta = self.queue.pop(0)
        dv = u - self.v
        self.v += min(dv, self.accel * dt) if dv > 0 else max(dv, -self.decel * dt)
        turn = self.v * dt / self.radius
        self.psi += min(max(wrap_pi(beta - self.psi), -turn), turn)
        self.x = self.x + self.v * dt * np.array([math.cos(self.psi), math.sin(self.psi)])


def _drive(guard: P3Guard, rover: _Rover, target: np.ndarray, bearing_of, seconds: float, dt: float,
           speed: float = 1.2, period: int = 3) -> float:
    """Drive ``rover`` towards the bearings ``bearing_of(t, rover)`` at ``speed`` through the
    guard (a command every ``period`` steps); its closest distance to ``target`` [m]."""
    closest, cmd = math.inf, (0.0, rover.psi)
    for k in range(int(seconds / dt)):
        t = k * dt
        if k % period == 0:
            bearing = bearing_of(t, rover)
            v_meas = rover.v * np.array([math.cos(rover.psi), math.sin(rover.psi)])
            allowed, _ = guard.limit_heading(t, rover.x, speed, rover.psi, v_meas, bearing_rad=bearing)
            cmd = (allowed, bearing)
        rover.step(dt, *cmd)
        closest = min(closest, float(np.linalg.norm(target - rover.x)))
    return closest


@pytest.mark.parametrize("seed", range(12))
def test_a_turning_rover_braking_late_never_enters_the_guard_circle(seed: int) -> None:
    """A rover with a lag and a turning radius, driven at the target from random headings and
    distances and steered at random (including hard towards the target, a turn in progress when
    the guard cuts in): its stopping path never enters the circle."""
    rng = np.random.default_rng(seed)
    dt, lag_s, radius, decel = 0.01, 0.6, 0.8, 1.0
    target = np.zeros(2)
    params = GuardParams(R_GUARD, decel, lag_s + 0.03, 0.03, turn_radius_m=radius)
    guard = P3Guard(params, target)
    angle = rng.uniform(-math.pi, math.pi)
    start = target + rng.uniform(8.5, 12.0) * np.array([math.cos(angle), math.sin(angle)])
    psi = angle + math.pi + rng.uniform(-1.5, 1.5)  # roughly towards the target
    rover = _Rover(start, psi, 1.2, radius, decel, int(lag_s / dt))
    swerves = rng.uniform(-math.pi, math.pi, 10)

    def bearing_of(t: float, r: _Rover) -> float:
        to_target = math.atan2(float(target[1] - r.x[1]), float(target[0] - r.x[0]))
        return to_target + (swerves[int(t) % 10] if seed % 2 else 0.0)

    closest = _drive(guard, rover, target, bearing_of, 25.0, dt)
    assert closest >= R_GUARD - 1e-6, closest


def test_a_rover_passing_beside_the_circle_then_turned_into_it_keeps_out() -> None:
    """Tangential at 1.2 m/s just outside the circle (the old guard saw no inward speed), it is
    then told to turn hard at the target: its turn and its brake both stay outside."""
    dt, radius = 0.01, 0.8
    target = np.zeros(2)
    guard = P3Guard(GuardParams(R_GUARD, 1.0, 0.63, 0.03, turn_radius_m=radius), target)
    rover = _Rover(np.array([R_GUARD + 1.0, -6.0]), 0.5 * math.pi, 1.2, radius, 1.0, 60)

    def bearing_of(t: float, r: _Rover) -> float:
        return math.atan2(-float(r.x[1]), -float(r.x[0])) if t > 4.0 else 0.5 * math.pi

    assert _drive(guard, rover, target, bearing_of, 20.0, dt) >= R_GUARD - 1e-6
    # the inward-component guard alone lets the same rover in
    old = P3Guard(GuardParams(R_GUARD, 1.0, 0.63, 0.03), target)
    rover = _Rover(np.array([R_GUARD + 1.0, -6.0]), 0.5 * math.pi, 1.2, radius, 1.0, 60)
    assert _drive(old, rover, target, bearing_of, 20.0, dt) < R_GUARD


def test_with_a_turn_reserve_the_rover_stops_where_it_can_still_turn_away() -> None:
    """Head-on at the target, then (once stopped) told to go away: an Ackermann car that cannot
    reverse turns round, forward first, at its turning radius; the reserve kept it far enough out."""
    dt, radius, reserve = 0.01, 0.56, 0.7
    target = np.zeros(2)
    guard = P3Guard(GuardParams(R_GUARD, 1.0, 0.63, 0.03, turn_radius_m=radius, turn_reserve_m=reserve), target)
    rover = _Rover(np.array([12.0, 0.3]), math.pi, 1.2, reserve, 1.0, 60)

    def bearing_of(t: float, r: _Rover) -> float:
        to_target = math.atan2(-float(r.x[1]), -float(r.x[0]))
        return to_target if t < 10.0 else to_target + math.pi  # the recovery course: away from it

    closest = _drive(guard, rover, target, bearing_of, 30.0, dt)
    assert closest >= R_GUARD - 1e-6, closest
    assert float(np.linalg.norm(rover.x)) > R_GUARD + 3.0  # it did turn round and drive away


def test_a_turn_away_is_the_one_that_does_not_face_the_target_more_on_the_way() -> None:
    from mission.carrier.guard import turns_away
    north = 0.0  # the target due north of the robot
    assert turns_away(0.2, math.pi, north)  # facing it, a little right of it: back round to the right
    assert turns_away(-0.2, math.pi - 0.01, north)  # a little left of it: round to the left
    assert not turns_away(-0.2, 2.0, north)  # left of it, to a bearing back right: the turn crosses it
    assert not turns_away(0.2, 0.3, north)  # a bearing towards it is no turn away
    assert turns_away(2.0, -2.0, north)  # facing away, the turn stays behind
