"""The carrier's clock over real loopback Zenoh (mission.bus.timesync): signed pings and echoes
give the offset between two clocks that started apart, within its bound; a rogue's unsigned or
badly signed echoes are dropped and counted, and change nothing."""
from __future__ import annotations

import pytest
import zenoh

from mission.bus.auth import BusAuth
from mission.bus.timesync import ClockEcho, ClockPing, time_keys
from mission.time.clock import ScaledClock
from tests.support.zenoh_util import peer_pair, wait_for

pytestmark = pytest.mark.timeout(30)

AUTH = BusAuth(bytes.fromhex("5c" * 32), "p")
ROGUE = BusAuth(bytes.fromhex("a1" * 32), "p")
CARRIER_AHEAD_S = 1234.5  # the carrier's clock started this long before ours [s]


def test_signed_round_trips_give_the_carrier_clock_within_their_bound_and_forged_echoes_are_dropped() -> None:
    ours, theirs = ScaledClock(), ScaledClock(start_s=CARRIER_AHEAD_S)
    with peer_pair() as (a, b):
        echo = ClockEcho(a, "p", theirs, AUTH)
        ping = ClockPing(b, "p", ours, AUTH, period_s=0.05)
        _, echo_key = time_keys("p")
        rogue_pub = a.declare_publisher(echo_key)
        rogue = ROGUE.signer()
        try:
            got = wait_for(lambda: (e := ping.estimate()) is not None and ping.counters["echoes"] >= 5 and e,
                           what="five round trips")
            assert abs(got.offset_s - CARRIER_AHEAD_S) <= got.bound_s + 1e-3, got
            assert got.bound_s < 0.05, got  # loopback: a round trip of milliseconds
            for seq in range(1, 4):  # a rogue answers our pings with its clock 10 s off
                forged = f"{ping.counters['pings'] + seq} {ours.now() + CARRIER_AHEAD_S + 10.0!r}".encode()
                rogue_pub.put(forged)  # unsigned
                rogue_pub.put(forged, attachment=rogue.attachment(echo_key, forged))  # another key
            wait_for(lambda: ping.counters["dropped"].get("unsigned", 0) >= 3
                     and ping.counters["dropped"].get("signature", 0) >= 3, what="the forged echoes dropped")
            after = ping.estimate()
            assert after is not None and abs(after.offset_s - CARRIER_AHEAD_S) <= after.bound_s + 1e-3
            assert echo.counters["echoes"] >= 5 and not echo.counters["dropped"]
        finally:
            rogue_pub.undeclare()
            ping.close()
            echo.close()


def test_an_echo_answering_no_ping_of_ours_is_counted_and_never_used() -> None:
    ours = ScaledClock()
    with peer_pair() as (a, b):
        ping = ClockPing(b, "p", ours, None, period_s=10.0)  # one ping, at once
        _, echo_key = time_keys("p")
        pub = a.declare_publisher(echo_key, congestion_control=zenoh.CongestionControl.BLOCK)
        try:
            wait_for(lambda: ping.counters["pings"] >= 1, what="the first ping")
            wait_for(lambda: pub.matching_status.matching, what="the echo key matched")
            pub.put(b"999 5.0")  # no ping 999 was sent
            pub.put(b"1 nan")
            pub.put(b"\xff\xfe")
            wait_for(lambda: sum(ping.counters["dropped"].values()) >= 3, what="three bad echoes counted")
            assert ping.counters["dropped"] == {"unknown": 1, "nonfinite": 1, "decode": 1}
            assert ping.estimate() is None
        finally:
            pub.undeclare()
            ping.close()
