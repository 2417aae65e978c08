"""LANDING_TARGET: the deck's landing point, its encoding as PX4 reads it, the rate gate, and the
mission loop sending it while the relative estimate is converged (fake world, manual clock)."""
from __future__ import annotations

import math
import threading

import numpy as np
import pytest

from mission.config.schema import load_config, with_overrides
from mission.controller import MissionController
from mission.mavlink.env import mavlink
from mission.mavlink.px4 import encode_landing_target as encode, landing_target_reading as px4_reading
from mission.passenger.target import LandingTarget, deck_target
from mission.time.rate import RateGate
from mission.time.clock import ManualClock
from tests.conftest import CONFIGS
from tests.support.fake_vehicle import FakeWorld, TrueMarker


def wire(msg):
    """``msg`` packed and parsed back by a fresh pymavlink parser, as the vehicle receives it."""
    sender, receiver = mavlink.MAVLink(None, srcSystem=245, srcComponent=190), mavlink.MAVLink(None)
    data = msg.pack(sender)
    parsed = receiver.parse_buffer(bytearray(data))
    assert parsed is not None and len(parsed) == 1
    return parsed[0]


def test_deck_target_is_own_position_plus_relative_plus_dock_offset():
    t = deck_target([10.0, -2.0, -5.0], [3.0, 1.0, 4.5], [0.5, 0.0, -0.4], 12.345678)
    assert t is not None
    assert t.position_ned_m == pytest.approx((13.5, -1.0, -0.9))
    assert t.time_usec == 12_345_678
    assert t.yaw_rad is None


@pytest.mark.parametrize("own, rel, t_s", [
    ([math.nan, 0, 0], [0, 0, 0], 1.0), ([0, 0, 0], [0, math.inf, 0], 1.0), ([0, 0, 0], [0, 0, 0], math.nan),
    ([0, 0, 0], [0, 0, 0], -1.0)])
def test_deck_target_refuses_what_is_not_finite(own, rel, t_s):
    assert deck_target(own, rel, [0, 0, 0], t_s) is None


def test_encoded_message_is_what_px4_accepts_on_the_wire():
    msg = wire(encode(LandingTarget((13.5, -1.0, -0.9), 12_345_678, math.pi / 2)))
    assert msg.get_type() == "LANDING_TARGET"
    assert msg.position_valid == 1
    assert msg.frame == mavlink.MAV_FRAME_LOCAL_NED == 1
    assert msg.type == mavlink.LANDING_TARGET_TYPE_VISION_FIDUCIAL
    assert msg.time_usec == 12_345_678
    assert (msg.angle_x, msg.angle_y, msg.distance, msg.size_x, msg.size_y) == (0, 0, 0, 0, 0)
    assert list(msg.q) == pytest.approx([math.sqrt(0.5), 0, 0, math.sqrt(0.5)], abs=1e-7)
    reading = px4_reading(msg)
    assert reading.kind == "pose"
    assert reading.position_ned_m == pytest.approx((13.5, -1.0, -0.9), abs=1e-6)  # float32 on the wire
    assert reading.time_usec == 12_345_678


def test_px4_refuses_other_frames_and_reads_position_invalid_as_irlock():
    base = encode(LandingTarget((1.0, 2.0, 3.0), 5, None))
    assert list(base.q) == [1.0, 0.0, 0.0, 0.0]
    turned = encode(LandingTarget((1.0, 2.0, 3.0), 5, math.pi / 2))  # the deck heading east
    assert list(turned.q) == pytest.approx([math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)])
    other = wire(mavlink.MAVLink_landing_target_message(5, 0, mavlink.MAV_FRAME_BODY_FRD, 0, 0, 0, 0, 0, 1, 2, 3,
                                                        (1, 0, 0, 0), 2, 1))
    assert px4_reading(other).kind == "unsupported_frame" and px4_reading(other).position_ned_m is None
    invalid = wire(mavlink.MAVLink_landing_target_message(5, 0, mavlink.MAV_FRAME_LOCAL_NED, 0.1, 0.2, 3, 0, 0, 1, 2,
                                                          3, (1, 0, 0, 0), 2, 0))
    assert px4_reading(invalid).kind == "irlock"


def test_encode_refuses_float32_overflow():
    with pytest.raises(ValueError):
        encode(LandingTarget((1e39, 0.0, 0.0), 0))


def test_rate_gate_keeps_the_grid_and_restarts_after_a_gap():
    gate = RateGate(10.0)
    ticks = np.arange(0, 1.0 + 1e-9, 0.02)  # a 50 Hz loop
    sent = [t for t in ticks if gate.due(float(t))]
    assert len(sent) == 11 and np.allclose(np.diff(sent), 0.1)
    assert gate.due(5.0) and not gate.due(5.02) and gate.due(5.1)  # after a gap: once, then on the new grid
    never = RateGate(0.0)
    assert not any(never.due(float(t)) for t in ticks)


def fly(rate_hz: float, until_s: float = 8.0):
    """The demo mission with ``[relnav]`` on and a perfect marker, stopped (interrupted) after ``until_s``."""
    cfg = with_overrides(load_config(CONFIGS / "demo.toml"),
                         {"relnav.enabled": True, "relnav.landing_target_rate_hz": rate_hz})
    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(cfg.scenario.target, dtype=float))
    dock_offset = np.asarray(cfg.mission.dock_offset_ned_m, dtype=float)
    truth: list[tuple[float, np.ndarray]] = []  # the true dock point each tick
    stop = threading.Event()

    def on_tick(report) -> None:
        truth.append((report.t_s, world.carrier_ned_m + dock_offset))
        if report.t_s > until_s:
            stop.set()

    controller = MissionController(cfg, world, world.feed, clock, command_thread=False, stop=stop,
                                   sources=[TrueMarker(world, dock_offset)], on_tick=on_tick)
    controller.run()
    assert controller.step.relative is not None and controller.step.relative.estimator.estimate().converged
    return cfg, world, truth
def test_loop_sends_the_dock_point_at_the_configured_rate_while_converged():
    cfg, world, truth = fly(10.0)
    sent = world.landing_targets
    assert len(sent) > 20
    times = np.array([target.time_usec for _, target in sent]) / 1e6
    assert np.allclose(np.diff(times), 0.1, atol=0.5 / cfg.mission.rate_hz)  # 10 Hz from a faster loop
    truth_at = dict(truth)
    errors = []
    for t_sent, target in sent:
        near = min(truth_at, key=lambda k: abs(k - t_sent))
        errors.append(np.linalg.norm(np.asarray(target.position_ned_m) - truth_at[near]))
    # the carrier moves at most speed x one tick between the vehicle's sample and the send
    assert max(errors) < 0.1 + world.carrier_speed_m_s / cfg.mission.rate_hz, max(errors)


def test_loop_sends_nothing_at_rate_zero():
    _, world, _ = fly(0.0)
    assert world.landing_targets == []


def test_a_recovery_that_streams_the_deck_sets_rtl_precision_landing_and_puts_it_back():
    """PX4's Return (the offboard-loss action of a recovery) lands on the streamed deck only with
    RTL_PLD_MD > 0: set to opportunistic while the mission flies, put back at its end."""
    cfg = with_overrides(load_config(CONFIGS / "demo.toml"),
                         {"mission.final_action": "return", "relnav.enabled": True, "relnav.landing_target_rate_hz": 10.0})
    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(cfg.scenario.target, dtype=float))
    world.params["RTL_PLD_MD"] = 0.0
    stop = threading.Event()
    controller = MissionController(cfg, world, world.feed, clock, command_thread=False, stop=stop,
                                   on_tick=lambda r: stop.set() if r.t_s > 5.0 else None)
    controller.run()
    assert [(n, v) for _, n, v in world.param_sets if n == "RTL_PLD_MD"] == [("RTL_PLD_MD", 1.0), ("RTL_PLD_MD", 0.0)]
    assert controller.px4_params["RTL_PLD_MD"] == {"was": 0.0, "set": 1.0, "restored": 0.0}
    assert controller.px4_params["COM_OBL_RC_ACT"]["set"] == 3.0
