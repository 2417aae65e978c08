"""The Zenoh carrier bridge over real loopback sessions: codecs on the wire, validation and drop
counters, ordering, staleness, liveliness, the passenger's status, session configuration."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
import zenoh

from mission.bus.bridge import (
    CarrierFeed,
    CarrierPublisher,
    PassengerFeed,
    PassengerPublisher,
    keys,
    open_session,
    zenoh_config,
)
from mission.time.clock import ManualClock, ScaledClock
from mission.config.schema import ZenohSection, from_dict
from mission.errors import BusError, ConfigError, PortInUse
from mission.bus.wire import CarrierState, GeoOrigin, PassengerStatus
from mission.bus.ros2 import encode_odometry_cdr, ros2dds_odom_key
from tests.support.zenoh_util import LENIENT, endpoint, free_port, peer, peer_pair, wait_for, wait_matched
from tests.conftest import ROOT

pytestmark = pytest.mark.timeout(30)


def _state(seq: int, stamp: float | None = None, north: float = 1.0) -> CarrierState:
    return CarrierState(stamp if stamp is not None else 0.1 * seq, seq, "local_ned",
                        [north, 2.0, 0.0], [0.5, -0.5, 0.0], 0.25)


def _raw(n: int, **changes: object) -> bytes:
    obj: dict[str, object] = {"stamp": 0.1 * n, "seq": n, "frame": "local_ned",
                              "position": [float(n), 0.0, 0.0], "velocity": [0.0, 0.0, 0.0], "yaw": None}
    obj.update(changes)
    return json.dumps(obj).encode()


def test_json_states_flow_and_are_returned_in_local_ned() -> None:
    clock = ManualClock(10.0)
    with peer_pair() as (a, b), CarrierFeed(b, "p", clock, limits=LENIENT) as feed, CarrierPublisher(a, "p") as pub:
        assert feed.latest() is None
        wait_for(lambda: pub.matched, what="publisher matched")
        pub.publish(_state(1))
        rx = wait_for(feed.latest, what="a carrier state")
        assert rx.key == "marsupial/p/carrier/state"
        assert rx.state.seq == 1 and rx.state.frame == "local_ned" and rx.state.yaw_rad == 0.25
        np.testing.assert_array_equal(rx.state.position, [1.0, 2.0, 0.0])
        np.testing.assert_array_equal(rx.state.velocity_ned_m_s, [0.5, -0.5, 0.0])
        assert rx.rx_time_s == 10.0 and rx.age_s == 0.0 and not rx.stale
        assert wait_for(lambda: feed.alive, what="carrier token") is True
        c = feed.counters
        assert (c["received"], c["accepted"], c["dropped"]) == (1, 1, {})
        assert c["bound_source"] == f"{a.zid()}/{pub._state.id.eid}" and c["rejected_sources"] == {}


def test_cdr_odometry_from_a_ros_bridge_key_is_converted_enu_to_ned() -> None:
    clock = ManualClock()
    key = ros2dds_odom_key("robot1")  # as zenoh-bridge-ros2dds routes /robot1/odom
    with peer_pair() as (a, b), CarrierFeed(b, "p", clock, encoding="cdr", key=key, limits=LENIENT) as feed:
        pub = a.declare_publisher(key)
        try:
            wait_matched(pub)
            # NED state -> Odometry (ENU position, FLU body twist in base_link) -> wire -> NED
            state = CarrierState(42.5, 0, "local_ned", [10.0, 20.0, -3.0], [1.0, 0.0, 0.0], 0.0)
            pub.put(encode_odometry_cdr(state, child_frame_id="base_link"))
            rx = wait_for(feed.latest, what="an odometry sample")
        finally:
            pub.undeclare()
        assert rx.key == "robot1/odom"
        np.testing.assert_allclose(rx.state.position, [10.0, 20.0, -3.0])
        np.testing.assert_allclose(rx.state.velocity_ned_m_s, [1.0, 0.0, 0.0], atol=1e-12)
        assert rx.state.stamp_s == pytest.approx(42.5) and rx.state.yaw_rad == pytest.approx(0.0)
        assert feed.counters["accepted"] == 1


def test_carrier_publisher_cdr_round_trip() -> None:
    with peer_pair() as (a, b), CarrierFeed(b, "p", ManualClock(), encoding="cdr", limits=LENIENT) as feed, \
            CarrierPublisher(a, "p", "cdr") as pub:
        wait_for(lambda: pub.matched)
        pub.publish(CarrierState(3.0, 0, "local_ned", [4.0, -5.0, 0.0], [1.0, 1.0, 0.0], math.pi / 4))
        rx = wait_for(feed.latest)
        np.testing.assert_allclose(rx.state.position, [4.0, -5.0, 0.0], atol=1e-12)
        np.testing.assert_allclose(rx.state.velocity_ned_m_s, [1.0, 1.0, 0.0], atol=1e-12)


def test_wgs84_states_are_converted_through_the_origin_or_dropped_without_one() -> None:
    with peer_pair() as (a, b), CarrierFeed(b, "p", ManualClock(), limits=LENIENT) as feed:
        pub = a.declare_publisher(keys("p").carrier_state)
        try:
            wait_matched(pub)
            pub.put(_raw(1, frame="wgs84", position=[47.001, 8.0, 395.0]))
            wait_for(lambda: feed.counters["dropped"].get("origin") == 1, what="origin drop")
            assert feed.latest() is None
            feed.set_origin(GeoOrigin(47.0, 8.0, 400.0))
            pub.put(_raw(2, frame="wgs84", position=[47.001, 8.0, 395.0]))
            rx = wait_for(feed.latest)
        finally:
            pub.undeclare()
        np.testing.assert_allclose(rx.state.position, [111.194927, 0.0, 5.0], atol=1e-5)
        assert rx.state.frame == "local_ned"


def test_malformed_and_out_of_order_samples_are_dropped_counted_and_never_returned() -> None:
    bad = [
        (b"\x00\xffgarbage", "decode"),
        (b'{"stamp": 9.0, "seq": 90, "frame": "local_ned", "position": [NaN, 0, 0], "velocity": [0, 0, 0]}', "nonfinite"),
        (_raw(91, position=["1", 0, 0]), "type"),
        (_raw(92, seq="92"), "type"),
        (json.dumps({"stamp": 9.3, "seq": 93, "frame": "local_ned", "velocity": [0, 0, 0]}).encode(), "missing"),
        (_raw(94, frame="ecef"), "frame"),
        (_raw(95, position=[1.0, 2.0]), "shape"),
        (_raw(5), "stale_seq"),  # duplicate of the accepted seq 5
        (_raw(3), "stale_seq"),  # older
        (_raw(6, stamp=0.2), "stale_stamp"),  # newer seq but older stamp
    ]
    with peer_pair() as (a, b), CarrierFeed(b, "p", ManualClock(), limits=LENIENT) as feed:
        pub = a.declare_publisher(keys("p").carrier_state)
        try:
            wait_matched(pub)
            pub.put(_raw(5))
            wait_for(feed.latest)
            for payload, _ in bad:
                pub.put(payload)
            wait_for(lambda: feed.counters["received"] == 1 + len(bad), what="all samples received")
            assert feed.latest().state.seq == 5  # type: ignore[union-attr]
            pub.put(_raw(7))
            wait_for(lambda: feed.latest().state.seq == 7)  # type: ignore[union-attr]
        finally:
            pub.undeclare()
    expected: dict[str, int] = {}
    for _, reason in bad:
        expected[reason] = expected.get(reason, 0) + 1
    c = feed.counters
    assert c["dropped"] == expected
    assert c["accepted"] == 2 and c["received"] == 2 + len(bad)


def test_age_grows_when_the_publisher_stops_and_stale_is_flagged_not_hidden() -> None:
    clock = ManualClock()
    with peer_pair() as (a, b), CarrierFeed(b, "p", clock, max_age_s=0.5, limits=LENIENT) as feed, CarrierPublisher(a, "p") as pub:
        wait_for(lambda: pub.matched)
        pub.publish(_state(1))
        first = wait_for(feed.latest)
        assert first.age_s == 0.0 and not first.stale
        clock.advance(0.3)
        assert feed.latest().age_s == pytest.approx(0.3) and not feed.latest().stale  # type: ignore[union-attr]
        clock.advance(0.4)
        late = feed.latest()
        assert late is not None and late.state.seq == 1  # still returned: the controller decides
        assert late.age_s == pytest.approx(0.7) and late.stale
        pub.publish(_state(2))
        fresh = wait_for(lambda: (r := feed.latest()) is not None and r.state.seq == 2 and r)
        assert fresh.age_s == 0.0 and not fresh.stale


def test_age_on_a_scaled_clock_grows_in_simulated_seconds() -> None:
    clock = ScaledClock(speed=20.0)
    with peer_pair() as (a, b), CarrierFeed(b, "p", clock, max_age_s=0.5, limits=LENIENT) as feed, CarrierPublisher(a, "p") as pub:
        wait_for(lambda: pub.matched)
        pub.publish(_state(1))
        wait_for(feed.latest)
        # 0.5 simulated seconds are 25 ms of wall time at speed 20
        stale = wait_for(lambda: (r := feed.latest()) is not None and r.stale and r, timeout_s=2.0)
        assert stale.age_s > 0.5


def test_liveliness_goes_false_when_the_publishers_session_closes_and_ordering_restarts() -> None:
    ep = endpoint(free_port())
    b = peer(listen=[ep])
    try:
        with CarrierFeed(b, "p", ManualClock(), limits=LENIENT) as feed:
            a = peer(connect=[ep])
            pub = CarrierPublisher(a, "p")
            wait_for(lambda: pub.matched)
            pub.publish(_state(10, stamp=100.0))
            wait_for(feed.latest)
            assert wait_for(lambda: feed.alive is True, what="alive") is True
            assert feed.alive_over_interval() is True
            a.close()  # no undeclare: a closed (or killed) process drops its token
            wait_for(lambda: feed.alive is False, what="token gone")
            # A restarted carrier counts from 0 again on its own clock: accepted.
            a2 = peer(connect=[ep])
            try:
                with CarrierPublisher(a2, "p") as pub2:
                    wait_for(lambda: pub2.matched)
                    wait_for(lambda: feed.alive is True, what="alive again")
                    # a tick after the outage still learns of it, once (the token is back by then)
                    assert feed.alive_over_interval() is False and feed.alive_over_interval() is True
                    pub2.publish(_state(0, stamp=0.0, north=-7.0))
                    rx = wait_for(lambda: (r := feed.latest()) is not None and r.state.seq == 0 and r)
                    assert rx.state.position[0] == -7.0
            finally:
                a2.close()
        assert feed.counters["dropped"] == {}
    finally:
        b.close()


def test_passenger_status_and_phase_flow_to_the_carrier_side() -> None:
    clock = ManualClock(1.0)
    phases: list[str] = []
    with peer_pair() as (a, b):
        # declared before the feed: once the publisher matches the feed, it knows this one too
        phase_sub = a.declare_subscriber(keys("p").passenger_phase, lambda s: phases.append(s.payload.to_string()))
        try:
            with PassengerFeed(a, "p", clock, max_age_s=1.0) as feed, PassengerPublisher(b, "p") as pub:
                wait_for(lambda: pub.matched)
                wait_for(lambda: feed.alive is True, what="passenger token")
                pub.publish(PassengerStatus("RIDING", 5.0, 1, [1, 2, -1.5], [0.5, 0, 0]))
                rx = wait_for(feed.latest)
                assert rx.status.phase == "RIDING" and not rx.status.separated and rx.status.anchor_ned_m is None
                pub.publish(PassengerStatus("SEPARATED", 5.1, 2, [1, 2, -1.6], [0.5, 0, -1], True, [1.0, 2.0, 0.0]))
                rx = wait_for(lambda: (r := feed.latest()) is not None and r.status.seq == 2 and r)
                assert rx.status.separated
                np.testing.assert_array_equal(rx.status.anchor_ned_m, [1.0, 2.0, 0.0])
                wait_for(lambda: phases == ["RIDING", "SEPARATED"], what="phase texts")
                c = feed.counters
                assert (c["received"], c["accepted"], c["dropped"], c["signed"]) == (2, 2, {}, False)
                assert c["bound_source"] == f"{b.zid()}/{pub._state.id.eid}"
        finally:
            phase_sub.undeclare()


def test_the_carrier_binds_the_passenger_that_began_on_the_deck_and_a_flood_elsewhere_changes_nothing() -> None:
    """A source that starts by claiming RIDING never binds; once the real passenger is bound (3
    statuses before riding), a flood of SEPARATED/ABORT with higher sequence numbers from another
    session is dropped as "source" and never makes the real statuses stale."""
    clock = ManualClock(1.0)
    BLOCK = zenoh.CongestionControl.BLOCK
    before = frozenset({"PREFLIGHT", "STREAMING", "ARMING", "OFFBOARD", "JOIN"})
    with peer_pair() as (a, b), PassengerFeed(a, "p", clock, bind_phases=before, bind_samples=3) as feed, \
            PassengerPublisher(b, "p", zenoh.CongestionControl.BLOCK) as pub:  # counted exactly: nothing dropped
        wait_for(lambda: pub.matched)
        key = keys("p").passenger_state
        riding = PassengerStatus("RIDING", 0.5, 10**6, [0, 0, -1.5], [0, 0, 0])
        for k in range(5):  # a rogue that rides from the start (no source_info: "anonymous")
            a.put(key, riding.model_copy(update={"seq": 10**6 + k}).to_json(), congestion_control=BLOCK)
        wait_for(lambda: feed.counters["dropped"].get("unbound", 0) == 5, what="5 unbound")
        for seq, phase in enumerate(["PREFLIGHT", "STREAMING", "STREAMING", "RIDING"], start=1):
            pub.publish(PassengerStatus(phase, 0.1 * seq, seq, [0, 0, -1.5], [0, 0, 0]))
            if seq == 3:  # bound now
                wait_for(lambda: feed.counters["bound_source"] is not None, what="bound")
                for k in range(50):  # the flood, between the real statuses
                    fake = "SEPARATED" if k % 2 else "ABORT"
                    a.put(key, PassengerStatus(fake, 9.0, 10**7 + k, [0, 0, 0], [0, 0, 0], fake == "SEPARATED").to_json(),
                          congestion_control=BLOCK)
        wait_for(lambda: (r := feed.latest()) is not None and r.status.seq == 4, what="the real RIDING")
        wait_for(lambda: feed.counters["dropped"].get("source", 0) == 50, what="the flood counted")
        c = feed.counters
        assert c["accepted"] == 2 and c["dropped"] == {"unbound": 7, "source": 50}, c
        assert c["rejected_sources"] == {"anonymous": 50}


def test_session_configuration_is_loopback_only_by_default() -> None:
    conf = zenoh_config(ZenohSection())
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    assert json.loads(conf.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7448", "tcp/127.0.0.1:0"]
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7448"]
    router = zenoh_config(ZenohSection(mode="router"))
    assert json.loads(router.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7447"]
    client = zenoh_config(ZenohSection(mode="client"))
    assert json.loads(client.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7447"]
    explicit = zenoh_config(ZenohSection(listen=["tcp/127.0.0.1:1234"]))
    assert json.loads(explicit.get_json("listen/endpoints")) == ["tcp/127.0.0.1:1234"]


def test_config_file_is_the_base_and_endpoint_flags_replace_its_endpoints(tmp_path) -> None:

    fleet = ROOT / "configs" / "zenoh" / "fleet_client.json5"
    conf = zenoh_config(ZenohSection(config_file=str(fleet)))
    assert json.loads(conf.get_json("mode")) == "client"
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7447"]
    conf = zenoh_config(ZenohSection(config_file=str(fleet), connect=["tcp/127.0.0.1:9999"]))
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/127.0.0.1:9999"]
    with pytest.raises(ConfigError, match="zenoh.config_file"):
        zenoh_config(ZenohSection(config_file=str(tmp_path / "missing.json5")))
    broken = tmp_path / "broken.json5"
    broken.write_text("{ mode: ")
    with pytest.raises(ConfigError, match="zenoh.config_file"):
        zenoh_config(ZenohSection(config_file=str(broken)))


def test_errors_are_translated_at_the_boundary() -> None:
    with pytest.raises(ConfigError, match="zenoh.listen"):  # the schema refuses it at load
        from_dict({"zenoh": {"listen": ["not an endpoint"]}})
    with pytest.raises(ConfigError, match="zenoh.listen"):  # and what gets past it, Zenoh's refusal is translated
        zenoh_config(ZenohSection.model_construct(listen=["not an endpoint"]))
    port = free_port()
    first = peer(listen=[endpoint(port)])
    try:
        with pytest.raises(PortInUse):
            peer(listen=[endpoint(port)])  # port taken: a peer refuses to start, naming the holder
    finally:
        first.close()
    with pytest.raises(ConfigError, match="zenoh.pair"):
        keys("a/b")


def test_invalid_subscription_key_is_a_bus_error() -> None:
    s = peer(listen=["tcp/127.0.0.1:0"])
    try:
        with pytest.raises(BusError):
            CarrierFeed(s, "p", ManualClock(), key="bad//key")
    finally:
        s.close()



def test_rendezvous_default_lets_two_peers_with_the_same_config_meet() -> None:
    # The default [zenoh] section: same config in both processes, no router. A test port
    # stands in for the default tcp/127.0.0.1:7448.
    section = ZenohSection(rendezvous=endpoint(free_port()))
    first = open_session(section)  # binds the rendezvous port
    try:
        second = open_session(section)  # cannot bind it (harmless), connects to it
        try:
            with CarrierFeed(first, "p", ManualClock(), limits=LENIENT) as feed, CarrierPublisher(second, "p") as pub:
                wait_for(lambda: pub.matched)
                pub.publish(_state(1))
                assert wait_for(feed.latest).state.seq == 1
        finally:
            second.close()
    finally:
        first.close()
