"""A flight's rangefinder feed, without sockets: DISTANCE_SENSOR -> DownwardRange
(:func:`mission.mavlink.telemetry.downward_range`), the drops it counts, the feed over a
listener (:class:`mission.cli.rangefinder.RangefinderFeed`), and the mock vehicle's encoding read
back (:func:`sim.vehicle.telemetry.distance_sensor`)."""
from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any, Callable

import pytest

from mission.cli.rangefinder import RangefinderFeed
from mission.mavlink.env import mavlink
from mission.mavlink.telemetry import RANGE_DROPS, downward_range
from mission.phases.measurements import DownwardRange
from sim.vehicle import telemetry as tel

DOWN = mavlink.MAV_SENSOR_ROTATION_PITCH_270


def _msg(current_cm: int = 123, *, boot_ms: int = 5_000, low: int = 10, high: int = 1_000, orientation: int = DOWN,
         covariance: int = 9, quality: int = 0) -> Any:
    return mavlink.MAVLink_distance_sensor_message(boot_ms, low, high, current_cm, mavlink.MAV_DISTANCE_SENSOR_LASER, 0,
                                                   orientation, covariance, signal_quality=quality)


def test_a_downward_range_is_read_in_metres_at_its_capture_on_the_link_clock():
    r = downward_range(_msg(123, boot_ms=5_040), clock_offset_s=100.25, default_sigma_m=0.05)
    assert isinstance(r, DownwardRange)
    assert r.range_m == 1.23 and r.capture_t_s == pytest.approx(105.29, abs=1e-12)
    assert r.sigma_m == pytest.approx(0.03)  # 9 cm^2
    assert downward_range(_msg(covariance=100), 0.0, 0.05).sigma_m == pytest.approx(0.10)  # type: ignore[union-attr]
    for unknown in (0, 255):  # UINT8_MAX (MAVLink), 0 (PX4 with no variance)
        assert downward_range(_msg(covariance=unknown), 0.0, 0.05).sigma_m == 0.05  # type: ignore[union-attr]
    assert downward_range(_msg(10), 0.0, 0.05).range_m == 0.10  # type: ignore[union-attr]  # the limits are inside
    assert downward_range(_msg(1_000), 0.0, 0.05).range_m == 10.0  # type: ignore[union-attr]
    for quality in (0, 2, 100):
        assert isinstance(downward_range(_msg(quality=quality), 0.0, 0.05), DownwardRange)


@pytest.mark.parametrize("msg, offset, reason", [
    (_msg(orientation=0), 0.0, "other_orientation"),  # forward
    (_msg(orientation=24), 0.0, "other_orientation"),  # upward (PITCH_90)
    (_msg(quality=1), 0.0, "invalid_signal"),
    (_msg(9), 0.0, "out_of_range"),
    (_msg(1_001), 0.0, "out_of_range"),
    (_msg(low=0, high=0, current_cm=0), 0.0, "malformed"),
    (_msg(low=500, high=400, current_cm=450), 0.0, "malformed"),
    (SimpleNamespace(time_boot_ms=1, min_distance=1, max_distance=100, current_distance=50.5, orientation=DOWN,
                     covariance=9), 0.0, "malformed"),  # a float where the wire has an integer
    (SimpleNamespace(time_boot_ms=1, min_distance=-1, max_distance=100, current_distance=50, orientation=DOWN,
                     covariance=9), 0.0, "malformed"),
    (SimpleNamespace(time_boot_ms=1, min_distance=1, max_distance=100), 0.0, "malformed"),  # fields missing
    (_msg(), None, "unclocked"),
    (_msg(), math.nan, "unclocked"),
])
def test_what_is_dropped_and_why(msg: Any, offset: float | None, reason: str):
    assert reason in RANGE_DROPS
    assert downward_range(msg, offset, 0.05) == reason


class _Link:
    """What the feed needs of a :class:`~mission.mavlink.link.VehicleLink`: its listeners and its vehicle clock."""

    def __init__(self, offset_s: float | None) -> None:
        self.offset_s = offset_s
        self.listeners: list[Callable[[Any], None]] = []

    def add_listener(self, callback: Callable[[Any], None]) -> None:
        self.listeners.append(callback)

    @property
    def state(self) -> SimpleNamespace:
        return SimpleNamespace(vehicle_clock_offset_s=self.offset_s)

    def hear(self, msg: Any) -> None:
        for listener in self.listeners:
            listener(msg)


def test_the_feed_hands_each_reading_over_once_and_counts_the_drops():
    link = _Link(None)
    feed = RangefinderFeed(link, default_sigma_m=0.05)  # type: ignore[arg-type]
    link.hear(_msg())  # no vehicle clock yet
    link.offset_s = 2.0
    heartbeat = mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3)
    for msg in (_msg(150, boot_ms=1_000), heartbeat, _msg(orientation=0), _msg(quality=1), _msg(5), _msg(160, boot_ms=1_040),
                SimpleNamespace(get_type=lambda: "DISTANCE_SENSOR"), object()):
        link.hear(msg)  # neither a message without fields nor one that is no message raises
    got = feed.poll(3.1)
    assert [(m.capture_t_s, m.range_m) for m in got] == [(3.0, 1.5), (3.04, 1.6)]
    assert feed.poll(3.2) == []
    assert feed.counters == {"received": 8, "readings": 2, "other_orientation": 1, "invalid_signal": 1,
                             "out_of_range": 1, "malformed": 2, "unclocked": 1}
    feed.close()
    link.hear(_msg())
    assert feed.poll(3.3) == [] and feed.counters["received"] == 8


def test_the_mock_vehicle_sends_what_the_feed_reads():
    """The mock's DISTANCE_SENSOR (PX4's encoding) read back: the range to the centimetre, the
    capture to the millisecond, the sigma from the covariance; a sigma past 254 cm^2 goes as unknown."""
    packed = tel.distance_sensor(12.34, 1.2349, 0.03, 10.0)
    wire = mavlink.MAVLink(None)
    back = wire.decode(bytearray(packed.pack(mavlink.MAVLink(None, srcSystem=1, srcComponent=1))))
    assert (back.orientation, back.min_distance, back.max_distance, back.covariance, back.signal_quality) == (DOWN, 0, 1000, 9, 0)
    r = downward_range(back, 0.5, 0.05)
    assert isinstance(r, DownwardRange)
    assert (r.capture_t_s, r.range_m, r.sigma_m) == (pytest.approx(12.84), 1.23, pytest.approx(0.03))
    assert tel.distance_sensor(0.0, 1.0, 0.2, 10.0).covariance == 255  # 400 cm^2 does not fit
    assert tel.distance_sensor(0.0, 1.0, 0.159, 10.0).covariance == 253


def test_the_mission_asks_the_vehicle_for_every_range_only_with_the_feed():
    """PX4's onboard profile streams DISTANCE_SENSOR at 10 Hz: with the feed the mission asks 50 Hz
    (PX4's stream sends each new sample up to that), without it nothing."""
    from mission.mavlink.requests import DISTANCE_SENSOR_ID, RANGEFINDER_RATE_HZ, Px4Setup
    from mission.time.clock import ManualClock

    class Asked:
        def __init__(self) -> None:
            self.intervals: list[tuple[int, float]] = []

        def set_message_interval(self, msg_id: int, rate_hz: float) -> None:
            self.intervals.append((msg_id, rate_hz))

    for rangefinder in (True, False):
        vehicle = Asked()
        Px4Setup(vehicle, ManualClock(), telemetry_rate_hz=None, stop_unused=False, recovery=False,  # type: ignore[arg-type]
                 battery_reserve_pct=20.0, offboard_loss_return=False, rangefinder=rangefinder)._ask_streams()
        assert ((DISTANCE_SENSOR_ID, RANGEFINDER_RATE_HZ) in vehicle.intervals) is rangefinder
    assert (DISTANCE_SENSOR_ID, RANGEFINDER_RATE_HZ) == (132, 50.0)
