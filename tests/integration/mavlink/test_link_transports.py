"""VehicleLink's tlog, transports and MAVLink 2 signing, against a real pymavlink PX4-like peer over
real loopback sockets (the rest: test_link.py)."""
from __future__ import annotations

import logging
import socket
from pathlib import Path

import numpy as np
import pytest

from mission.core.setpoint import Setpoint
from mission.mavlink import px4
from mission.time.clock import ScaledClock
from mission.errors import LinkError
from mission.mavlink.link import LinkCounters, VehicleLink
from mission.mavlink.env import mavlink, mavutil
from sim.testing.fake_px4 import FakePx4 as Px4Peer
from sim.net import wait_for as eventually
from tests.integration.mavlink.conftest import ANY_PORT, link_threads


# ------------------------------------------------------------------------------ tlog, transports


def test_tlog_holds_everything_and_is_readable_by_pymavlink(tmp_path: Path) -> None:
    tlog = tmp_path / "flight.tlog"
    with VehicleLink(ANY_PORT, ScaledClock(1.0), tlog_path=tlog) as link, Px4Peer(link.port) as peer:
        link.wait_vehicle(5.0)
        link.wait_until(lambda s: s.position_ned_m is not None, 5.0)
        link.send(Setpoint.velocity_only(np.array([0.5, -0.5, 0.0])))
        link.set_mode("OFFBOARD")
        eventually(lambda: peer.received("SET_POSITION_TARGET_LOCAL_NED"), what="setpoint")
        sent = link.counters.tx_messages
    log = mavutil.mavlink_connection(str(tlog))
    try:
        messages = []
        while (m := log.recv_match(blocking=False)) is not None:
            messages.append(m)
    finally:
        log.close()
    ours = [m for m in messages if (m.get_srcSystem(), m.get_srcComponent()) == (1, 191)]
    theirs = [m for m in messages if (m.get_srcSystem(), m.get_srcComponent()) == (1, 1)]
    assert len(ours) == sent
    assert [m.get_seq() for m in ours] == [i % 256 for i in range(sent)]  # one sequence, no gaps
    assert {"HEARTBEAT", "SET_POSITION_TARGET_LOCAL_NED", "COMMAND_LONG"} <= {m.get_type() for m in ours}
    assert {"HEARTBEAT", "LOCAL_POSITION_NED", "COMMAND_ACK"} <= {m.get_type() for m in theirs}
    sp = next(m for m in ours if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED")
    assert (sp.vx, sp.vy, sp.vz, sp.type_mask) == (0.5, -0.5, 0.0, 3527)
    stamps = [m._timestamp for m in messages]
    assert stamps == sorted(stamps)
    assert abs(stamps[-1] - stamps[0]) < 60.0 and stamps[0] > 1.6e9  # epoch seconds, this session


def test_udpout_link_talks_first() -> None:
    peer = Px4Peer(url="udpin:127.0.0.1:0")
    port = peer.conn.port.getsockname()[1]
    with peer, VehicleLink(f"udpout:127.0.0.1:{port}", ScaledClock(10.0)) as link:
        assert link.wait_vehicle(5.0).system_id == 1
        assert link.command_long(px4.MAV_CMD_REQUEST_MESSAGE, 148.0) == 0


def test_tcp_link() -> None:
    peer = Px4Peer(url="tcpin:127.0.0.1:0")
    port = peer.conn.listen.getsockname()[1]
    with peer, VehicleLink(f"tcp:127.0.0.1:{port}", ScaledClock(1.0)) as link:
        link.wait_vehicle(5.0)
        link.set_mode("OFFBOARD")
        assert link.state.mode == "OFFBOARD"


def test_open_errors_become_link_errors() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        busy = VehicleLink(f"udpin:127.0.0.1:{taken.getsockname()[1]}", ScaledClock(1.0))
        with pytest.raises(LinkError, match="cannot open"):
            busy.open()
        assert not busy.is_open
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as closed_port:
        closed_port.bind(("127.0.0.1", 0))
        refused = closed_port.getsockname()[1]
    with pytest.raises(LinkError, match="cannot open"):
        VehicleLink(f"tcp:127.0.0.1:{refused}", ScaledClock(1.0)).open()
    for url in ("udpin:nonsense", "udpin:127.0.0.1:notaport", "carrier-pigeon:1", "udpout:127.0.0.1:70000"):
        with pytest.raises(LinkError):
            VehicleLink(url, ScaledClock(1.0)).open()


def test_close_releases_the_port_and_is_idempotent() -> None:
    link = VehicleLink(ANY_PORT, ScaledClock(1.0)).open()
    port = link.port
    assert port and link_threads()
    link.close()
    link.close()
    assert link.port is None and not link.is_open
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as again:
        again.bind(("127.0.0.1", port))  # would raise EADDRINUSE if the link kept it
    assert isinstance(link.counters, LinkCounters)
    with pytest.raises(LinkError, match="opens once"):
        link.open()


# ------------------------------------------------------------------------------ signing

KEY = bytes(range(100, 132))


def test_signed_link_signs_everything_and_keeps_the_key_out_of_the_tlog(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG)
    tlog = tmp_path / "signed.tlog"
    with VehicleLink(ANY_PORT, ScaledClock(10.0), signing_key=KEY, tlog_path=tlog) as link, \
            Px4Peer(link.port, signing_key=KEY) as peer:
        link.wait_vehicle(5.0)
        assert link.command_long(px4.MAV_CMD_REQUEST_MESSAGE, 148.0) == 0  # signed ACK accepted
        link.wait_until(lambda s: s.position_ned_m is not None, 5.0)  # signed telemetry accepted
        link.send(Setpoint.velocity_only(np.array([1.0, 0.0, 0.0])))
        eventually(lambda: peer.received("SET_POSITION_TARGET_LOCAL_NED"), what="signed setpoint")
        from_link = peer.received()
        assert from_link and all(m.get_signed() for m in from_link)  # verified with the key
        assert KEY.hex() not in repr(link)
    data = tlog.read_bytes()
    assert KEY not in data and KEY.hex().encode() not in data
    assert KEY.hex() not in caplog.text and repr(KEY) not in caplog.text


def test_signed_link_refuses_everything_unsigned_heartbeat_included() -> None:
    with VehicleLink(ANY_PORT, ScaledClock(1.0), signing_key=KEY) as link, Px4Peer(link.port) as peer:
        eventually(lambda: link.counters.rx_unsigned >= 30, what="unsigned packets refused")
        assert link.vehicle_id is None and link.state.heartbeat_rx_s is None and link.state.position_ned_m is None
        assert link.counters.rx_bad_signature == 0 and link.signing_problem() is None
        assert peer.received() == []  # nothing unsigned gave it our reply address


def test_signed_link_follows_the_signed_vehicle_and_ignores_unsigned_spoofs() -> None:
    """Unsigned HEARTBEATs copying the vehicle's id, claiming POSCTL, from another address: they
    neither change the vehicle's mode nor move the reply address."""
    with VehicleLink(ANY_PORT, ScaledClock(1.0), signing_key=KEY) as link, \
            Px4Peer(link.port, signing_key=KEY) as vehicle:
        link.wait_vehicle(5.0)
        with Px4Peer(link.port, sysid=1, heartbeat_hz=50.0, position_hz=0.0) as spoofer:
            spoofer.custom_mode = px4.custom_mode_of("POSCTL")
            eventually(lambda: link.counters.rx_unsigned >= 20, what="spoofed HEARTBEATs refused")
            assert link.state.mode == "AUTO.LOITER"
            link.send(Setpoint.velocity_only(np.array([0.5, 0.0, 0.0])))
            eventually(lambda: vehicle.received("SET_POSITION_TARGET_LOCAL_NED"), what="setpoint at the vehicle")
            assert spoofer.received() == []


def test_wrong_key_is_refused_with_its_own_reason() -> None:
    with VehicleLink(ANY_PORT, ScaledClock(1.0), signing_key=KEY) as link, \
            Px4Peer(link.port, signing_key=bytes(32)) as peer:
        eventually(lambda: link.counters.rx_bad_signature >= 10, what="badly signed packets refused")
        assert link.vehicle_id is None and link.state.position_ned_m is None
        problem = link.signing_problem()
        assert problem is not None and "sysid 1 compid 1 signs with another key" in problem
        assert peer.received() == []  # we never answered it


def test_a_forged_packet_stamped_in_the_future_does_not_lock_the_vehicle_out() -> None:
    """pymavlink records a stream's timestamp before checking the signature; the link undoes that
    for refused packets, so a forgery stamped far ahead cannot make the real vehicle's packets
    look replayed."""
    forger = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    forger.signing.secret_key, forger.signing.sign_outgoing = bytes(32), True
    forger.signing.link_id, forger.signing.timestamp = 0, 2**47  # ~44 years ahead
    forged = mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3).pack(forger)
    with VehicleLink(ANY_PORT, ScaledClock(1.0), signing_key=KEY) as link:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            for _ in range(3):
                sock.sendto(forged, ("127.0.0.1", link.port))
            eventually(lambda: link.counters.rx_bad_signature >= 3, what="forgeries refused")
        finally:
            sock.close()
        with Px4Peer(link.port, signing_key=KEY):
            assert link.wait_vehicle(5.0).system_id == 1


def test_bad_signing_key_is_refused_without_echoing_it() -> None:
    with pytest.raises(ValueError) as info:
        VehicleLink(ANY_PORT, ScaledClock(1.0), signing_key=b"secret-too-short")
    assert "secret" not in str(info.value)


class Relay:
    """A UDP socket that forwards every datagram it receives to ``port`` on 127.0.0.1 (from its own
    address), and counts what comes back to it: an attacker forwarding one link to another."""

    def __init__(self, port: int) -> None:
        import threading

        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.port, self.target, self.forwarded, self.answers = self.sock.getsockname()[1], port, 0, 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="relay")
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data, (_, port) = self.sock.recvfrom(65535)
            except OSError:
                continue
            if port == self.target:
                self.answers += 1  # the link answered the relay: its reply address moved here
            else:
                self.sock.sendto(data, ("127.0.0.1", self.target))
                self.forwarded += 1

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.sock.close()


def test_the_vehicles_own_gcs_link_forwarded_to_our_port_moves_nothing() -> None:
    """The cross-link replay: the mock vehicle signs both its links with one key (as PX4 does); an
    attacker forwards its GCS link's packets (link id 0, timestamps of their own) to our port. On
    main they were accepted, each moved the reply address to the attacker, and the real link (then
    behind on the one shared stream) was refused. Now: counted as another link and ignored, the
    reply address stays with the vehicle's onboard link (id 1), which is never refused, and our
    setpoints keep reaching the vehicle."""
    from sim.vehicle.mock import MockVehicle, VehicleOptions

    with VehicleLink(ANY_PORT, ScaledClock(5.0), signing_key=KEY) as link:
        relay = Relay(link.port)
        try:
            opts = VehicleOptions(target=f"127.0.0.1:{link.port}", gcs_target=f"127.0.0.1:{relay.port}", signing_key=KEY,
                                  speed=5.0)
            with MockVehicle(opts) as v:
                link.wait_vehicle(5.0)
                eventually(lambda: link.counters.rx_other_link >= 100, 10.0, "forwarded GCS-link packets counted")
                before = link.state.position_rx_s
                for _ in range(20):
                    link.send(Setpoint.hold_still())
                eventually(lambda: v.counters["setpoints_accepted"] >= 20, 5.0, "our setpoints at the vehicle")
                eventually(lambda: (link.state.position_rx_s or 0.0) > (before or 0.0), 5.0, "telemetry goes on")
                c = link.counters
                assert relay.forwarded >= 100 and relay.answers == 0, (relay.forwarded, relay.answers)
                assert c.peer_moves == 0 and c.rx_bad_signature == 0 and c.rx_unsigned == 0, c
        finally:
            relay.close()
