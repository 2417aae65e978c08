"""The rangefinder feed of a flight over UDP on 127.0.0.1: the mock vehicle's downward rangefinder
(``VehicleOptions.rangefinder``, ``[world.rangefinder]``) sent as DISTANCE_SENSOR, read by the
controller's feed (:class:`mission.cli.rangefinder.RangefinderFeed`) on a real
:class:`~mission.mavlink.link.VehicleLink`: the ranges against the mock's truth (the deck's top
under it, then the ground once the deck moved away), and each capture stamped on the link's clock
the latency before it arrived."""
from __future__ import annotations

import statistics
from typing import Callable

from mission.cli.rangefinder import RangefinderFeed
from mission.config.relnav import RangefinderSection
from mission.mavlink.link import VehicleLink
from mission.mavlink.requests import DISTANCE_SENSOR_ID
from mission.phases.measurements import DownwardRange
from mission.time.clock import ScaledClock
from sim.net import wait_for as eventually
from sim.vehicle.mock import MockVehicle, VehicleOptions
from sim.vehicle.physics.deck import DeckMotion, DeckSpec

ANY_PORT = "udpin:127.0.0.1:0"
SENSOR = RangefinderSection()  # 25 Hz, 3 cm, 30 ms late, 2 % lost
STANDS_D_M = -2.0  # the vehicle stands on a platform 2 m above the ground (d = 0)
DECK_HEIGHT_M = 0.8  # the deck's top 0.8 m above the carrier's position at d = 0: 1.2 m under the vehicle
# the link's vehicle-clock offset may run this far ahead of the truth after a stalled receiver (it may grow
# 0.1 s/s between LOCAL_POSITION_NEDs): no capture reads earlier than its latency by more [s]
SLACK_S = 0.015


def _collect(feed: RangefinderFeed, into: list[tuple[float, DownwardRange]], clock: ScaledClock, count: int) -> Callable[[], bool]:
    """A check for ``eventually``: poll the feed (stamping each poll on the link clock) until ``count`` readings came."""
    def check() -> bool:
        now = clock.now()
        into.extend((now, m) for m in feed.poll(now) if isinstance(m, DownwardRange))
        return len(into) >= count
    return check


def test_the_mock_vehicles_ranges_reach_the_feed_over_udp() -> None:
    clock = ScaledClock(1.0)
    deck = [DeckMotion((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0)]  # under the vehicle
    heard: list[tuple[float, int]] = []  # (link clock at arrival [s], time_boot_ms) of each DISTANCE_SENSOR
    with VehicleLink(ANY_PORT, clock, target_system=1) as link:
        link.add_listener(lambda msg: heard.append((clock.now(), int(msg.time_boot_ms)))
                          if msg.get_type() == "DISTANCE_SENSOR" else None)
        feed = RangefinderFeed(link, default_sigma_m=0.05)
        vehicle = MockVehicle(VehicleOptions(bind="127.0.0.1:0", target=f"127.0.0.1:{link.port}",
                                             start_ned=(0.0, 0.0, STANDS_D_M), rangefinder=SENSOR,
                                             deck=DeckSpec(height_m=DECK_HEIGHT_M, radius_m=0.5)))
        vehicle.follow_deck(lambda: deck[0])
        with vehicle:
            link.wait_vehicle(10.0)
            link.set_message_interval(DISTANCE_SENSOR_ID, 50.0)  # as the mission asks (Px4Setup): accepted
            over: list[tuple[float, DownwardRange]] = []
            eventually(_collect(feed, over, clock, 30), timeout_s=10.0, what="30 ranges over the deck")
            truth = vehicle.snapshot().position_ned_m
            deck[0] = DeckMotion((3.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0)  # 3 m away: the ground under the vehicle
            moved_at = clock.now()
            after: list[tuple[float, DownwardRange]] = []
            eventually(_collect(feed, after, clock, 40), timeout_s=10.0, what="40 ranges after the deck moved")
            counters, sent = feed.counters, vehicle.counters["ranges_sent"]
        feed.close()

    assert tuple(truth) == (0.0, 0.0, STANDS_D_M)
    over_m = [m.range_m for _, m in over]
    ground_m = [m.range_m for t, m in after if m.capture_t_s > moved_at + 0.2]  # captured well after the move
    assert abs(statistics.mean(over_m) - (-DECK_HEIGHT_M - STANDS_D_M)) < 0.02  # 1.2 m, 30 ranges of 3 cm
    assert len(ground_m) >= 20 and abs(statistics.mean(ground_m) - (0.0 - STANDS_D_M)) < 0.02  # 2.0 m
    assert max(abs(r - 1.2) for r in over_m) < 5 * SENSOR.sigma_m and max(abs(r - 2.0) for r in ground_m) < 5 * SENSOR.sigma_m
    assert statistics.pstdev(over_m) < 2 * SENSOR.sigma_m and all(m.sigma_m == SENSOR.sigma_m for _, m in over + after)
    # captured on the sensor's 40 ms grid of the vehicle's boot clock (a lost one skips a slot), in order;
    # on the link's clock to within the few ms its vehicle-clock offset wanders
    boot_ms = [ms for _, ms in heard]  # (the first capture is the first physics step's, at 5 ms)
    assert [ms for ms in boot_ms if ms % 40 and ms != 5] == [] and all(b > a for a, b in zip(boot_ms, boot_ms[1:]))
    readings = [m for _, m in over + after]
    steps = [b.capture_t_s - a.capture_t_s for a, b in zip(readings, readings[1:])]
    off_grid = [d for d in steps if round(d / 0.04) < 1 or abs(d - 0.04 * round(d / 0.04)) > SLACK_S]
    assert off_grid == []
    early = [(polled, m.capture_t_s) for polled, m in over + after if polled < m.capture_t_s + SENSOR.latency_s - SLACK_S]
    assert early == []
    # each arrived the latency after its capture (the capture moved onto the link's clock by the
    # offset the link learned from LOCAL_POSITION_NED): as a rule to the ms, never much earlier
    offset = link.state.vehicle_clock_offset_s
    assert offset is not None
    delays = sorted(rx - (boot_ms / 1000.0 + offset) for rx, boot_ms in heard)
    # (measured 0.030 s; the upper bound catches a capture stamped 50 ms or more early, not a loaded
    # machine's late wake-ups: how fast the loop sends is no correctness of the stamps)
    assert SENSOR.latency_s - 0.002 < statistics.median(delays) < SENSOR.latency_s + 0.05
    assert delays[len(delays) // 10] > SENSOR.latency_s - 0.003 and delays[0] > SENSOR.latency_s - SLACK_S
    assert counters["readings"] == len(heard) >= 70 and counters["received"] == counters["readings"]
    assert sent >= counters["readings"]
