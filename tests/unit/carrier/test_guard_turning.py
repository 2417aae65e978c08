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


def _drive_at_the_target(speed_m_s: float, delay_s: float, decel_m_s2: float, overshoot_m_s: float = 0.0,
                         seconds: float = 20.0) -> tuple[list[float], float]:
    """A robot heading straight at a target 4 m above its plane, asked ``speed_m_s`` through the
    PX4 rover's guard (b c - 1 = 7 m, 1 m/s^2, ``delay_s``, turning radius 0.3 m, reserve 0.9 m, 30
    Hz): it does each command ``delay_s`` later (plus ``overshoot_m_s`` while it drives), changing
    its speed at most at ``decel_m_s2``. The commands sent, and its closest approach [m]."""
    dt = 1.0 / 30.0
    target = np.array([30.0, 0.0, -4.0])
    g = P3Guard(GuardParams(7.0, 1.0, delay_s, dt, turn_radius_m=0.3, turn_reserve_m=0.9), target)
    lag = int(round(delay_s / dt))
    x, v, sent, closest = 0.0, speed_m_s, [speed_m_s] * (lag + 1), math.inf
    for k in range(int(seconds / dt)):
        out, _ = g.limit_heading(k * dt, np.array([x, 0.0, 0.0]), speed_m_s, 0.0, np.array([v, 0.0, 0.0]),
                                 bearing_rad=0.0)
        sent.append(out)
        asked = sent[-1 - lag] + (overshoot_m_s if sent[-1 - lag] > 0 else 0.0)
        v += max(-decel_m_s2 * dt, min(decel_m_s2 * dt, asked - v))
        x += v * dt
        closest = min(closest, float(np.linalg.norm(target - np.array([x, 0.0, 0.0]))))
    return sent[lag + 1:], closest


def test_a_rover_that_follows_its_commands_late_is_slowed_not_stopped_dead() -> None:
    """PX4's SIH rover: 0.8 s late, braking at 1 m/s^2 (and faster). Measured against the cap alone,
    the guard took the speed it still drove on the commands of 0.8 s ago for an overshoot, two
    ticks after the cap first bound, and stopped it dead from 1.2 m/s (its riding passenger then
    0.49-0.52 m off the dock). The commands in flight count: it is slowed along the cap."""
    sent, closest = _drive_at_the_target(1.2, 0.8, 1.0)
    first = next(i for i, s in enumerate(sent) if s < 1.2)
    braking = np.array(sent[first:])
    assert braking.min() == 0.0 or braking[-1] < 0.05  # it does stop, in the end
    stopped = int(np.argmax(braking < 0.01))
    assert np.all(np.diff(braking[:stopped]) <= 1e-9)  # never back up once the guard slows it
    assert stopped * (1.0 / 30.0) > 0.5  # a ramp down (0.63 s), not a slam (before: 0 within 0.1 s)
    assert closest >= 7.0 - 1e-6  # and the circle holds


def test_a_rover_faster_than_anything_it_was_told_is_still_braked_outright() -> None:
    sent, closest = _drive_at_the_target(1.2, 0.8, 1.0, overshoot_m_s=0.3)
    assert 0.0 in sent[:sent.index(0.0) + 1] and sent.index(0.0) < len(sent) - 1
    first = next(i for i, s in enumerate(sent) if s < 1.2)
    assert sent.index(0.0) - first <= 3  # 1.5 m/s on 1.2 asked: an overshoot, stopped at once
    assert closest >= 7.0 - 1e-6
