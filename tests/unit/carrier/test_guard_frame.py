"""The frame the carrier's P3 guard runs in (mission/carrier/frames.py): the passenger's, by the
bias its status shares, while that bias is fresh, converged, plausible and steady; otherwise the
carrier's own frame with the margin widened; every sample dropped and every fall back counted.
And the carrier's step guarding a lying passenger (RIDING for ever) in either frame."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mission.carrier.backends.sim import SimRobot
from mission.carrier.frames import FrameParams, GuardFrame, HeardBias
from mission.carrier.guard import GuardParams, P3Guard
from mission.carrier.modes import PassengerView
from mission.carrier.step import CarrierStepper
from mission.config.schema import Config, from_dict
from mission.errors import ConfigError
from mission.phases.phase import Phase
from mission.time.clock import ManualClock

PARAMS = FrameParams("passenger", max_age_s=1.0, max_sigma_m=0.3, max_bias_m=4.0, max_step_m=0.3, tau_s=0.0,
                     settle_s=0.0, unaligned_margin_m=2.0)  # no smoothing, no settling: each gate alone
B = np.array([1.5, -1.0, 0.4])  # [m] the carrier's GNSS frame minus the passenger's


def _heard(bias: np.ndarray = B, sigma: float = 0.1, stamp: float = 0.0, age: float = 0.05) -> HeardBias:
    return HeardBias(np.asarray(bias, dtype=float), sigma, stamp, age)


def _settled(frame: GuardFrame, heard: HeardBias | None, now: float) -> str:
    frame.hear(heard)
    return frame.settle(now)


def test_the_own_frame_is_the_guard_as_it_always_was_whatever_the_passenger_shares() -> None:
    frame = GuardFrame(dataclasses.replace(PARAMS, frame="own"))
    assert _settled(frame, _heard(), 1.0) == ""
    assert not frame.passenger and frame.widen_m == 0.0 and frame.shift_ned_m(3, False).tolist() == [0, 0, 0]
    assert frame.dropped == {"unconverged": 0, "implausible": 0, "jump": 0}


def test_a_usable_bias_moves_the_guard_into_the_passengers_frame_and_none_widens_the_margin() -> None:
    frame = GuardFrame(PARAMS)
    assert _settled(frame, None, 0.0) == "" and frame.why == "none"
    assert frame.widen_m == 2.0 and frame.shift_ned_m(3, True).tolist() == [0, 0, 0]
    assert "passenger's frame" in _settled(frame, _heard(), 0.1)
    assert frame.passenger and frame.widen_m == 0.0
    assert frame.shift_ned_m(3, False).tolist() == B.tolist()
    assert frame.shift_ned_m(3, True).tolist() == [1.5, -1.0, 0.0]  # a planar carrier's height is the scenario's
    assert frame.shift_ned_m(2, True).tolist() == [1.5, -1.0]


@pytest.mark.parametrize("bad, reason", [
    ({"age": 1.5}, "stale"),
    ({"sigma": 0.31}, "unconverged"),
    ({"sigma": math.nan}, "unconverged"),
    ({"bias": [4.0, 0.5, 0.0]}, "implausible"),
    ({"bias": [1.0, math.nan, 0.0]}, "implausible"),
    ({"bias": B + [0.31, 0.0, 0.0]}, "jump"),
])
def test_each_gate_falls_back_to_the_own_frame_with_the_margin_widened_and_counts(bad: dict, reason: str) -> None:
    frame = GuardFrame(PARAMS)
    _settled(frame, _heard(stamp=0.0), 0.0)
    assert frame.passenger
    change = _settled(frame, _heard(**{"stamp": 0.02, **bad}), 0.02)
    assert "own frame" in change and reason in change
    assert not frame.passenger and frame.why == reason and frame.widen_m == 2.0
    assert frame.shift_ned_m(3, False).tolist() == [0, 0, 0]
    assert frame.fallbacks[reason] == 1
    assert frame.dropped.get(reason, 0) == (0 if reason == "stale" else 1)
    # the same sample heard again is not counted again, and the frame stays its own
    assert _settled(frame, _heard(**{"stamp": 0.02, **bad}), 0.05) == ""
    assert frame.fallbacks[reason] == 1 and frame.dropped.get(reason, 0) == (0 if reason == "stale" else 1)
    assert frame.summary()["passenger"] is False and frame.summary()["fallbacks"][reason] == 1


def test_the_last_bias_shared_holds_while_fresh_then_goes_stale() -> None:
    """A passenger stops sharing once its estimate is not converged (its marker out of the camera,
    a second after it separates): its statuses go on without the bias, the last one holds for
    carrier.p3_bias_max_age_s on the carrier's clock."""
    frame = GuardFrame(PARAMS)
    _settled(frame, _heard(stamp=0.0, age=0.05), 0.05)
    for now in (0.5, 0.99):
        assert _settled(frame, None, now) == "" and frame.passenger  # heard at 0.0: 1.0 s is the limit
    assert "stale" in _settled(frame, None, 1.01) and frame.fallbacks["stale"] == 1 and frame.widen_m == 2.0
    assert _settled(frame, None, 2.0) == "" and frame.why == "stale"


def test_a_planar_carrier_judges_the_bias_it_uses_its_horizontal_part() -> None:
    tall = np.array([2.5, -2.5, 3.0])  # 4.9 m in all, 3.5 m horizontally: max_bias_m is 4
    flat = GuardFrame(PARAMS, planar=True)
    assert "passenger's frame" in _settled(flat, _heard(tall), 0.0)
    assert flat.shift_ned_m(3, True).tolist() == [2.5, -2.5, 0.0]
    assert _settled(flat, _heard(tall + [0.0, 0.0, 1.0], stamp=0.03), 0.03) == ""  # its height may swing
    solid = GuardFrame(PARAMS)
    _settled(solid, _heard(tall), 0.0)
    assert not solid.passenger and solid.dropped["implausible"] == 1


def test_the_guard_s_bias_is_smoothed_and_settles_before_it_is_used_and_after_a_jump() -> None:
    """Each sample moves the guard's bias by at most max_step (1 - exp(-dt / tau)); a run of steady
    samples settle_s long is needed before the guard uses them, from the start and after a jump."""
    params = FrameParams("passenger", max_age_s=1.0, max_sigma_m=0.3, max_bias_m=4.0, max_step_m=0.3, tau_s=1.0,
                         settle_s=0.5, unaligned_margin_m=2.0)
    frame, dt = GuardFrame(params), 1.0 / 30.0
    rng = np.random.default_rng(3)
    t, used = 0.0, []
    for k in range(90):  # 3 s of samples swinging 0.05 m about B
        t = k * dt
        _settled(frame, _heard(B + rng.normal(0.0, 0.05, 3).clip(-0.08, 0.08), stamp=t, age=0.0), t)
        assert frame.passenger == (t >= 0.5 - 1e-9) and (frame.why in ("", "settling"))
        if frame.passenger:
            used.append(frame.shift_ned_m(3, False))
    steps = np.linalg.norm(np.diff(used, axis=0), axis=1)
    assert steps.max() <= 0.3 * -math.expm1(-dt / 1.0) + 1e-12  # max_step (1 - exp(-dt / tau))
    assert float(np.linalg.norm(used[-1] - B)) < 0.08  # the swing averaged out
    jumped = B + [0.0, 1.0, 0.0]  # a reset, or a hostile passenger: 1 m at once
    t += dt
    assert "jump" in _settled(frame, _heard(jumped, stamp=t, age=0.0), t)
    start = t
    while True:
        t += dt
        change = _settled(frame, _heard(jumped, stamp=t, age=0.0), t)
        if frame.passenger:
            break
        assert frame.why == "settling" and frame.widen_m == 2.0
    assert t - start == pytest.approx(0.5, abs=dt) and "passenger's frame" in change
    assert frame.shift_ned_m(3, False).tolist() == pytest.approx(jumped.tolist())
    assert frame.dropped["jump"] == 1 and frame.fallbacks["jump"] == 1


def test_the_guard_runs_on_the_position_moved_into_the_passengers_frame_and_on_the_widened_radius() -> None:
    params = GuardParams(7.0, 1.0, 0.3, 1 / 30)
    target = np.array([20.0, 0.0, 0.0])
    x_c, v = np.array([10.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])
    frame = GuardFrame(PARAMS)
    guarded = P3Guard(params, target, planar=False, frame=frame)
    widened = P3Guard(GuardParams(5.0, 1.0, 0.3, 1 / 30), target, planar=False)
    assert guarded.cap(0.0, x_c, v)[:2] == widened.cap(0.0, x_c, v)[:2]  # no bias: own frame, radius 7 - 2
    _settled(frame, _heard(), 0.0)
    plain = P3Guard(params, target, planar=False)
    cap, h, n = guarded.cap(0.1, x_c, v)
    cap0, h0, n0 = plain.cap(0.1, x_c - B, v)
    assert (cap, h) == (cap0, h0) and np.allclose(n, n0)
    assert h == pytest.approx(float(np.linalg.norm(target - (x_c - B))) - 7.0)


def _cfg(**carrier: object) -> Config:
    return from_dict({
        "scenario": {"carrier_start": [0.0, 0.0, 0.0], "target": [20.0, 0.0, 0.0], "carrier_mode": "stop"},
        "safety": {"carrier_max_accel_m_s2": 1.0, "carrier_max_speed_m_s": 2.0},
        "carrier": {"rate_hz": 30.0, "max_speed_m_s": 2.0, "p3_margin_m": 1.0, **carrier},
    })


def _lying_ride(cfg: Config, bias: HeardBias | None, seconds: float = 40.0) -> tuple[CarrierStepper, np.ndarray]:
    """A passenger that claims RIDING for ever (it never separates): the carrier drives at the target
    until its guard stops it. Returns the stepper and where the carrier stands [m] (its own frame)."""
    dt, clock = 1.0 / 30.0, ManualClock()
    robot = SimRobot(cfg, clock)
    stepper = CarrierStepper(cfg, False)
    for k in range(int(seconds / dt)):
        clock.advance(dt)
        robot.advance(dt)
        heard = None if bias is None else HeardBias(bias.bias_ned_m, bias.sigma_m, k * dt, 0.02)
        stepper.update_mode(PassengerView(Phase.RIDING, False, bias=heard))
        robot.command(stepper.decide(robot.own_state(), dt, 0.0, clock.now()).tracked)
        stepper.frame.account(robot.own_state().position_ned_m[:3], stepper.legs.targets)
    return stepper, robot.own_state().position_ned_m[:3]


def test_the_carrier_parks_at_the_guard_radius_in_the_frame_it_guards_in() -> None:
    target = np.array([20.0, 0.0, 0.0])
    bias = _heard(np.array([-1.5, 0.0, 0.0]))  # the passenger's frame has the carrier 1.5 m nearer the target
    own, x_own = _lying_ride(_cfg(), bias)
    assert 6.95 <= float(np.linalg.norm(target - x_own)) <= 7.3  # b c - 1, in its own frame: the bias ignored
    aligned, x = _lying_ride(_cfg(p3_frame="passenger", p3_unaligned_margin_m=2.0), bias)
    assert aligned.frame.passenger and aligned.frame.steps["own"] <= 31  # settling its first second
    in_passenger = float(np.linalg.norm(target - (x - bias.bias_ned_m)))
    assert 6.95 <= in_passenger <= 7.3  # b c - 1 where the target is
    assert float(np.linalg.norm(target - x)) == pytest.approx(in_passenger + 1.5, abs=0.01)  # 1.5 m farther in its own
    assert aligned.frame.summary()["closest_target_distance_m"] == pytest.approx(in_passenger, abs=0.01)
    loose, x = _lying_ride(_cfg(p3_frame="passenger", p3_unaligned_margin_m=2.0), _heard(sigma=0.6))
    assert 4.95 <= float(np.linalg.norm(target - x)) <= 5.3  # unconverged: its own frame, b c - 1 - 2
    assert loose.frame.dropped["unconverged"] == int(40.0 * 30.0) and loose.frame.steps["passenger"] == 0


def test_the_unaligned_margin_leaves_a_guard_radius() -> None:
    with pytest.raises(ConfigError, match="p3_unaligned_margin_m"):
        _cfg(p3_frame="passenger", p3_unaligned_margin_m=7.0)


def test_the_next_legs_start_is_measured_where_the_passenger_measures_it() -> None:
    """The carrier drives out for the next leg until its dock point is the leg-start distance from
    the target in the guards' frame: by the passenger's usable bias, else in its own frame
    ``p3_unaligned_margin_m`` farther. In its own frame alone, a carrier 6.5 m off the passenger's
    frame stood where the passenger saw the dock point inside b c, and both waited for ever."""
    from mission.carrier.legs import Legs
    from mission.config.legs import REPOSITION_SPARE_M

    target = np.array([0.0, 0.0, 0.0])
    frame = GuardFrame(PARAMS)
    legs = Legs([target], [], GuardParams(radius_m=5.0, brake_decel_m_s2=1.0), True, np.zeros(3), 10.0, frame)
    start = 10.0 + REPOSITION_SPARE_M
    far = np.array([start + 0.1, 0.0, 0.0])  # far enough in its own frame
    _settled(frame, None, 0.0)  # no usable bias: its own frame, 2 m farther out
    assert legs.reposition_velocity(far, 1.0).tolist() == [1.0, 0.0, 0.0]
    assert not legs.reposition_velocity(far + [2.0, 0.0, 0.0], 1.0).any()
    _settled(frame, _heard(bias=[1.5, 0.0, 0.0]), 0.1)  # the passenger has the carrier 1.5 m nearer the target
    assert frame.passenger
    assert legs.reposition_velocity(far, 1.0).tolist() == [1.0, 0.0, 0.0]
    assert legs.reposition_velocity(far + [1.5, 0.0, 0.0], 1.0).tolist() == [0.0, 0.0, 0.0]
    assert legs.turn_velocity(far, math.pi, 0.5) is None  # no room to turn yet, where the passenger has it
    turn = legs.turn_velocity(far + [1.5, 0.0, 0.0], 0.0, 0.5)  # out far enough: it turns towards the target
    assert turn is not None and np.allclose(turn, [-0.5, 0.0, 0.0])


def test_a_passenger_that_still_waits_has_the_leg_start_moved_out() -> None:
    """The carrier stands at the leg's start by its own frame while the passenger, its frame
    farther off than the carrier allowed for, still waits in TRANSIT: after LEG_START_PATIENCE_S
    standing the start moves LEG_START_STEP_M farther out (and again, up to LEG_START_EXTRA_MAX_M),
    so the two do not wait for each other until the mission's timeout; the next leg starts afresh."""
    from mission.carrier.legs import LEG_START_EXTRA_MAX_M, LEG_START_PATIENCE_S, LEG_START_STEP_M, Legs
    from mission.config.legs import REPOSITION_SPARE_M

    targets = [np.array([0.0, 0.0, 0.0]), np.array([50.0, 0.0, 0.0])]
    legs = Legs(targets, [], GuardParams(radius_m=5.0, brake_decel_m_s2=1.0), True, np.zeros(3), 10.0)
    at = np.array([10.0 + REPOSITION_SPARE_M + 0.1, 0.0, 0.0])  # at the start, in its own frame
    assert not legs.reposition_velocity(at, 1.0).any()
    dt, t, x, moved = 0.05, 0.0, at.copy(), []
    while t < 2.5 * LEG_START_PATIENCE_S:  # the carrier drives as told, at 1 m/s
        if legs.wait_out(x, t):
            moved.append(round(t, 6))
        x = x + legs.reposition_velocity(x, 1.0) * dt
        t += dt
    # it stood 20 s, drove 2 m out (2 s), stood 20 s again
    assert moved == [pytest.approx(LEG_START_PATIENCE_S), pytest.approx(2 * LEG_START_PATIENCE_S + 2.0, abs=0.1)], moved
    assert legs.extra_m == 2 * LEG_START_STEP_M and x[0] == pytest.approx(10.0 + REPOSITION_SPARE_M + 2 * LEG_START_STEP_M, abs=0.06)
    assert legs.reposition_velocity(at, 1.0).tolist() == [1.0, 0.0, 0.0]  # where it first stood: out again
    # a carrier still driving out is not waited on; a gap in the calls starts the wait afresh
    out = x + [1.0, 0.0, 0.0]
    assert not legs.wait_out(at, t) and not legs.wait_out(out, t + 5.0)
    assert not legs.wait_out(out, t + 5.0 + LEG_START_PATIENCE_S - 0.1)
    for k in range(1000):  # 500 s standing far out
        legs.wait_out(out + [100.0, 0.0, 0.0], 1000.0 + k * 0.5)
    assert legs.extra_m == LEG_START_EXTRA_MAX_M  # bounded
    assert legs.follow(1) and legs.extra_m == 0.0


def test_the_carrier_s_law_drives_at_the_target_where_the_passenger_has_it() -> None:
    """The carrier's law runs in the guards' frame: with the passenger's frame 4 m across the
    carrier's own, it drives at the target where the passenger (and the targets' file) has it,
    not where its own GNSS has it. In its own frame, with the frames 7-9 m apart along its course,
    it stood 4-5 m from the target by its GNSS while the passenger saw the dock point 11-14 m out,
    beyond b c, and never separated (seed 3's 59 of the Monte-Carlo, 3 minutes)."""
    across = _heard(np.array([0.0, 4.0, 0.0]))  # the carrier's GNSS frame less the passenger's: 4 m east
    _, x_own = _lying_ride(_cfg(), across, seconds=4.0)
    assert abs(float(x_own[1])) < 0.01  # straight at the target by its own GNSS
    aligned, x = _lying_ride(_cfg(p3_frame="passenger", p3_unaligned_margin_m=2.0), across, seconds=4.0)
    _, x_later = _lying_ride(_cfg(p3_frame="passenger", p3_unaligned_margin_m=2.0), across, seconds=5.0)
    assert aligned.frame.passenger  # (its first second in its own frame, settling)
    seen = x - across.bias_ned_m  # where the passenger has the carrier at 4 s
    to_target = math.atan2(0.0 - float(seen[1]), 20.0 - float(seen[0]))
    moved = x_later - x
    assert math.atan2(float(moved[1]), float(moved[0])) == pytest.approx(to_target, abs=math.radians(2.0))
    assert to_target > math.radians(8.0)  # which its own GNSS would not have it drive at
