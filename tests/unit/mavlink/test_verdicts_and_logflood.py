"""The armed/landed beliefs of the telemetry reducer (no single sample decides) and the per-packet
log line limiter, with hand-built messages and a hand-moved clock."""
from __future__ import annotations

import logging

from mission.mavlink import px4, telemetry
from mission.mavlink import receiver as logflood
from mission.mavlink.env import mavlink


def _hb(armed: bool) -> object:
    return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4,
                                             px4.base_mode_of("OFFBOARD", armed), px4.custom_mode_of("OFFBOARD"), 4, 3)


def _ess(state: int) -> object:
    return mavlink.MAVLink_extended_sys_state_message(0, state)


def test_a_vehicle_on_the_ground_disarmed_is_believed_so_at_once() -> None:
    tm = telemetry.reduce(telemetry.Telemetry(), _hb(False), 0.0)
    tm = telemetry.reduce(tm, _ess(px4.LANDED_ON_GROUND), 0.05)
    assert not tm.believed_armed and tm.believed_on_ground


def test_in_flight_one_sample_of_either_source_decides_nothing_both_do() -> None:
    tm = telemetry.reduce(telemetry.Telemetry(), _hb(True), 0.0)
    tm = telemetry.reduce(tm, _ess(px4.LANDED_IN_AIR), 0.1)
    one = telemetry.reduce(tm, _ess(px4.LANDED_ON_GROUND), 0.2)
    assert one.believed_armed and not one.believed_on_ground
    other = telemetry.reduce(tm, _hb(False), 0.2)
    assert other.believed_armed and not other.believed_on_ground
    both = telemetry.reduce(other, _ess(px4.LANDED_ON_GROUND), 0.3)
    assert not both.believed_armed and both.believed_on_ground
    signed = telemetry.reduce(telemetry.reduce(telemetry.Telemetry(signed=True), _hb(True), 0.0), _ess(px4.LANDED_ON_GROUND), 0.1)
    assert signed.believed_on_ground
    back = telemetry.reduce(both, _hb(True), 0.4)
    assert back.believed_armed  # armed again: believed at once


def test_the_limiter_passes_a_burst_then_one_a_period_and_counts_the_rest() -> None:
    now = [0.0]
    limiter = logflood.LineLimiter(burst=3, period_s=1.0, now=lambda: now[0])

    def record(msg: str) -> logging.LogRecord:
        return logging.LogRecord("pymavlink.x", logging.INFO, "f", 1, msg, None, None)

    passed = [limiter.filter(record("sig mismatch")) for _ in range(10)]
    assert passed == [True] * 3 + [False] * 7
    assert limiter.filter(record("new stream"))  # another kind has its own budget
    now[0] = 1.0
    late = record("sig mismatch")
    assert limiter.filter(late) and "7 more like it held back" in late.getMessage()
    assert limiter.suppressed() == {"pymavlink.x: sig mismatch": 7} and limiter.suppressed_total() == 7
