"""A robot that moves along its heading turns round away from a target near it, not through it
(the tracking law's ``turn``, :meth:`mission.carrier.guard.P3Guard.away_turn`)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mission.carrier.frames import FrameParams, GuardFrame, HeardBias
from mission.carrier.guard import GuardParams, P3Guard
from mission.carrier.tracking import TURN_STEP_RAD, TrackingParams, track
from mission.core.geodesy import wrap_pi

ACKERMANN = TrackingParams("ackermann", heading_gain=2.0, max_yaw_rate_rad_s=1.5, min_speed_fraction=0.3,
                           wheelbase_m=0.321, max_steer_rad=0.5236)
TARGET = np.array([0.0, 0.0])
GUARD = P3Guard(GuardParams(5.0, 1.0, turn_radius_m=0.56, turn_reserve_m=0.9), TARGET)


def _at(distance_m: float, heading_deg: float) -> tuple[np.ndarray, float]:
    """A robot ``distance_m`` south of the target (which lies north of it, at bearing 0) heading
    ``heading_deg`` (from north, + east: the target lies that far on its left)."""
    return np.array([-distance_m, 0.0]), math.radians(heading_deg)


def test_a_turn_set_a_way_round_steers_that_way_a_right_angle_at_a_time():
    yaw, bearing = math.radians(150.0), math.radians(-30.0)
    u = 1.2 * np.array([math.cos(bearing), math.sin(bearing)])
    right, left, short = (track(u, yaw, ACKERMANN, t) for t in (1, -1, 0))
    assert right.yaw_rate_rad_s > 0 and wrap_pi(right.bearing_rad - yaw) == pytest.approx(TURN_STEP_RAD)
    assert left.yaw_rate_rad_s < 0 and wrap_pi(left.bearing_rad - yaw) == pytest.approx(-TURN_STEP_RAD)
    assert short.bearing_rad == pytest.approx(bearing)  # as it always was
    for cmd in (right, left):  # the setpoint a PX4 rover steers to is that bearing, at the creep's speed
        assert math.atan2(cmd.setpoint_ned_m_s[1], cmd.setpoint_ned_m_s[0]) == pytest.approx(cmd.bearing_rad)
        assert cmd.speed_m_s == pytest.approx(1.2 * 0.3)
    # a turn already going the way asked, or short of a right angle, is the shortest way's
    u2 = np.array([math.cos(yaw + 0.4), math.sin(yaw + 0.4)])
    a, b = track(u2, yaw, ACKERMANN, 1), track(u2, yaw, ACKERMANN, 0)
    assert (a.speed_m_s, a.yaw_rate_rad_s, a.bearing_rad) == (b.speed_m_s, b.yaw_rate_rad_s, b.bearing_rad)
    np.testing.assert_array_equal(a.setpoint_ned_m_s, b.setpoint_ned_m_s)


@pytest.mark.parametrize("heading_deg, bearing_deg, way", [
    (35.0, -135.0, 1),    # the target 35 deg on its left, the shortest way (left, 170 deg) through it: right round
    (-25.0, 145.0, -1),   # the target 25 deg on its right, the shortest way (right) through it: left round
    (35.0, -155.0, 0),    # the shortest way (right, 170 deg) already turns away
    (35.0, 100.0, 0),     # less than a right angle: the shortest way
    (35.0, -70.0, 0),     # a bearing within a right angle of the target's: no turn keeps away, the guard decides
    (150.0, -30.0, 0),    # facing away from it: the shortest turn stays in the back half
])
def test_near_the_target_it_turns_round_the_way_that_does_not_face_it(heading_deg, bearing_deg, way):
    x, yaw = _at(8.0, heading_deg)
    assert GUARD.away_turn(x, yaw, math.radians(bearing_deg), within_m=11.0) == way


def test_far_from_the_target_it_takes_the_shortest_way():
    x, yaw = _at(12.0, 35.0)
    assert GUARD.away_turn(x, yaw, math.radians(-135.0), within_m=11.0) == 0
    assert GUARD.away_turn(x, yaw, math.radians(-135.0), within_m=13.0) == 1


def _turn_round(x: np.ndarray, yaw: float, bearing: float, way_round: bool, speed_m_s: float = 0.8,
                dt_s: float = 0.02) -> float:
    """The closest [m] a kinematic Ackermann robot comes to the target turning onto ``bearing``."""
    closest = float(np.linalg.norm(x - TARGET))
    u = speed_m_s * np.array([math.cos(bearing), math.sin(bearing)])
    for _ in range(int(20.0 / dt_s)):
        turn = GUARD.away_turn(x, yaw, bearing, within_m=11.0) if way_round else 0
        cmd = track(u, yaw, ACKERMANN, turn)
        x = x + dt_s * cmd.speed_m_s * np.array([math.cos(yaw), math.sin(yaw)])
        yaw = wrap_pi(yaw + dt_s * cmd.yaw_rate_rad_s)
        closest = min(closest, float(np.linalg.norm(x - TARGET)))
    assert abs(wrap_pi(yaw - bearing)) < 0.05  # it got round
    return closest


@pytest.mark.parametrize("heading_deg", [35.0, -25.0, 10.0, -60.0])
def test_turning_round_away_closes_in_less_than_the_shortest_way(heading_deg):
    """Standing 8 m from the target, facing ``heading_deg`` off it, onto a course 170 deg round
    the target's side (away from it, tilted as a recovery heading cleared of another target is):
    the shortest way swings through the target's bearing (to 6.96-7.36 m); away round it does not
    (7.56-7.93 m)."""
    x, yaw = _at(8.0, heading_deg)
    bearing = wrap_pi(yaw - math.copysign(math.radians(170.0), heading_deg))
    short = _turn_round(x, yaw, bearing, way_round=False)
    round_away = _turn_round(x, yaw, bearing, way_round=True)
    assert round_away >= short + 0.15  # measured 0.19-0.97 m less closed (the creep's 0.56 m turning radius)
    assert round_away >= 8.0 - 0.56  # at most its turning radius, from facing the target 10 deg off


def test_the_side_of_the_target_is_judged_in_the_guards_frame():
    """The rover truly 8 m south of the target, heading north with the target 20 deg to its right;
    its own GNSS frame 5.8 m east of the passenger's puts the target 20 deg to its left. Onto a
    course 170 deg round to the left, the shortest way, it must keep that way (it turns away from
    the true target); judged in its own frame it would turn right round, through it."""
    bias = np.array([0.0, 5.8, 0.0])  # [m] the carrier's GNSS frame minus the passenger's
    truly = np.array([-8.0, -8.0 * math.tan(math.radians(20.0))])
    own_x = truly + bias[:2]
    yaw, bearing = 0.0, math.radians(-170.0)
    params = FrameParams("passenger", max_age_s=15.0, max_sigma_m=0.5, max_bias_m=8.0, max_step_m=0.5, tau_s=0.0,
                         settle_s=0.0, unaligned_margin_m=0.0)
    frame = GuardFrame(params)
    guard = P3Guard(GUARD.p, TARGET, planar=False, frame=frame)
    assert guard.away_turn(own_x, yaw, bearing, within_m=11.0) == 1  # no bias heard: its own frame, the wrong side
    frame.hear(HeardBias(bias, 0.1, stamp_s=1.0, age_s=0.0))
    assert frame.settle(1.0).startswith("P3 guard in the passenger's frame")
    assert guard.away_turn(own_x, yaw, bearing, within_m=11.0) == 0  # the target on its right: left is away
    frame.hear(None)
    frame.settle(1.0 + 15.5)  # the bias heard 15.5 s ago is stale: its own frame again
    assert guard.away_turn(own_x, yaw, bearing, within_m=11.0) == 1
