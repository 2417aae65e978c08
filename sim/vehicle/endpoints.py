"""UDP endpoints and the per-link MAVLink codec of the mock vehicle.

A :class:`VehicleLink` is one PX4-style MAVLink instance: a UDP socket bound to a local address,
sending to a target address from start-up and latching on the first peer that talks to it.
It owns its own MAVLink 2 codec (sequence numbers, signing state), parses each datagram on its
own (a truncated packet never poisons the next datagram) and classifies what it received.
Sending is one message per datagram, as PX4 does, unless the caller batches: then
:meth:`VehicleLink.queue` collects a step's packets and :meth:`VehicleLink.flush` sends them as
one datagram (the lockstep vehicle: a step is one instant of simulated time).
"""
from __future__ import annotations

import socket
from typing import Any

from mission.mavlink.codec import keep_replay_state_on_failure, new_codec, reset_parser, setup_signing
from mission.config.urls import Endpoint, parse_url
from mission.mavlink.env import mavlink
from mission.errors import LinkError
from mission.port_holder import is_addr_in_use, port_in_use

UNSIGNED_ALLOWED_IDS = frozenset({mavlink.MAVLINK_MSG_ID_HEARTBEAT, mavlink.MAVLINK_MSG_ID_RADIO_STATUS})
#: MAVLink 2 signing link id of each link: PX4 signs with its MAVLink instance number
#: (``mavlink_sign_control.cpp``: ``link_id = instance id``), and PX4 SITL starts the GCS link
#: first, then the onboard/API link (``px4-rc.mavlink``).
LINK_IDS = {"gcs": 0, "onboard": 1}


def parse_endpoint(text: str, default_scheme: str = "udpin") -> Endpoint:
    """A UDP endpoint in the URL forms pymavlink and MAVSDK use (:func:`mission.config.urls.parse_url`:
    ``HOST:PORT`` with ``default_scheme``, ``udpin:``, ``udpout:``, ``udp:`` = udpin, ``://``, an empty
    host = 127.0.0.1). Raises ValueError for anything else (the mock vehicle speaks UDP only)."""
    endpoint = parse_url(text, default_scheme)
    if endpoint.scheme not in ("udpin", "udpout"):
        raise ValueError(f"not a UDP endpoint (expected [udpin:|udpout:]HOST:PORT): {text!r}")
    return endpoint


class VehicleLink:
    """One MAVLink instance: socket, target address (latched on the first peer), codec.

    Signing (``signing_key``): outgoing packets carry this link's id (:data:`LINK_IDS`);
    incoming ones are checked against ``replay_streams``, the last signing timestamp seen per
    (link id, system, component), which every link of the vehicle shares as PX4's instances share
    one table (``global_mavlink_signing_streams``); a refused packet leaves it unchanged.
    """

    def __init__(self, name: str, bind: Endpoint, target: Endpoint | None, sysid: int, compid: int,
                 signing_key: bytes | None = None, replay_streams: dict | None = None) -> None:
        self.name = name
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        try:
            self.sock.bind(bind.address)
        except OSError as exc:
            self.sock.close()
            if is_addr_in_use(exc):
                raise port_in_use(f"mock vehicle {name} link", *bind.address) from None
            host, port = bind.address
            raise LinkError(f"cannot open mock vehicle {name} link on UDP {host}:{port}: {exc.strerror} "
                            "(is the host an address of this machine?)") from None
        self.sock.setblocking(False)
        self.target: tuple[str, int] | None = target.address if target else None
        self.latched = False
        self.last_peer_heartbeat_s = -1e9
        self.mav = new_codec(sysid, compid)
        self._queued: list[bytes] = []
        self._queued_counted = 0  # queued packets the caller counts as sent messages
        if signing_key is not None:
            setup_signing(self.mav, signing_key, sign_outgoing=True, unsigned_ids=UNSIGNED_ALLOWED_IDS,
                          link_id=LINK_IDS.get(name, 0))
            if replay_streams is not None:
                self.mav.signing.stream_timestamps = replay_streams
            keep_replay_state_on_failure(self.mav)

    @property
    def port(self) -> int:
        return int(self.sock.getsockname()[1])

    def latch(self, address: tuple[str, int]) -> None:
        """Answer the first peer that talks to this link from now on (PX4 SITL behaviour)."""
        if not self.latched:
            self.target, self.latched = address, True

    def parse(self, data: bytes) -> tuple[list[Any], int]:
        """Decode one datagram: (messages, count of leftover bytes of an incomplete packet).

        Messages include pymavlink's ``BAD_DATA`` (bad CRC, garbage, rejected signature) and
        ``UNKNOWN_<id>`` (ids outside the dialect) objects; nothing raises.
        """
        mav = self.mav
        try:
            messages = mav.parse_buffer(data) or []
        except Exception:  # noqa: BLE001  (no byte sequence may stop the vehicle)
            messages = [mavlink.MAVLink_bad_data(bytearray(data), "parser exception")]
        return messages, reset_parser(mav)

    def pack(self, msg: Any) -> bytes:
        """Encode ``msg`` with this link's sequence number (and signature, when signing)."""
        data = bytes(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) % 256
        return data

    def sendto(self, data: bytes, address: tuple[str, int]) -> bool:
        """Send a datagram; False on a socket error (counted by the caller, never raised)."""
        try:
            self.sock.sendto(data, address)
            return True
        except OSError:
            return False

    def queue(self, data: bytes, counted: bool = True) -> None:
        """Hold a packet for the next :meth:`flush` (``counted``: one of the caller's sent messages)."""
        self._queued.append(data)
        self._queued_counted += counted

    def flush(self) -> int:
        """Send the queued packets as one datagram to the target; the number of counted packets
        lost to a socket error (or to no target), 0 when sent."""
        if not self._queued:
            return 0
        data, lost = b"".join(self._queued), self._queued_counted
        self._queued.clear()
        self._queued_counted = 0
        return 0 if self.target is not None and self.sendto(data, self.target) else lost

    def close(self) -> None:
        self.sock.close()
