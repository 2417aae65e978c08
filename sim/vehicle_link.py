"""UDP endpoints and the per-link MAVLink codec of the mock vehicle.

A :class:`VehicleLink` is one PX4-style MAVLink instance: a UDP socket bound to a local address,
sending to a target address from start-up and latching on the first peer that talks to it.
It owns its own MAVLink 2 codec (sequence numbers, signing state), parses each datagram on its
own (a truncated packet never poisons the next datagram) and classifies what it received.
"""
from __future__ import annotations

import datetime
import socket
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from mission.mavlink_env import mavlink
from mission.errors import LinkError
from mission.port_holder import is_addr_in_use, port_in_use

SIGNING_EPOCH = datetime.datetime(2015, 1, 1, tzinfo=datetime.timezone.utc)
UNSIGNED_ALLOWED_IDS = frozenset({mavlink.MAVLINK_MSG_ID_HEARTBEAT, mavlink.MAVLINK_MSG_ID_RADIO_STATUS})
_SCHEMES = ("udpin", "udpout", "udp")


@dataclass(frozen=True)
class Endpoint:
    """A UDP endpoint: ``scheme`` is ``"udpin"`` (bind/listen) or ``"udpout"`` (send to)."""

    scheme: str
    host: str
    port: int

    @property
    def address(self) -> tuple[str, int]:
        return self.host, self.port


def parse_endpoint(text: str, default_scheme: str = "udpin") -> Endpoint:
    """Parse the URL forms pymavlink and MAVSDK use for UDP.

    Accepted: ``HOST:PORT``, ``udpin:HOST:PORT``, ``udpout:HOST:PORT``, ``udp:HOST:PORT``
    (= udpin, as in pymavlink), the same with ``://``, and an empty host (``:14540``) meaning
    127.0.0.1. A bare address takes ``default_scheme``.
    """
    rest, scheme = text.strip(), default_scheme
    for candidate in _SCHEMES:
        for sep in ("://", ":"):
            if rest.startswith(candidate + sep):
                scheme, rest = candidate, rest[len(candidate) + len(sep):]
                break
        else:
            continue
        break
    scheme = "udpin" if scheme == "udp" else scheme
    host, sep, port_text = rest.rpartition(":")
    if not sep or ":" in host or "/" in host or not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
        raise ValueError(f"not a UDP endpoint (expected [udpin:|udpout:]HOST:PORT): {text!r}")
    return Endpoint(scheme, host or "127.0.0.1", int(port_text))


def signing_timestamp_now() -> int:
    """MAVLink 2 signing timestamp: 10 us units since 2015-01-01 UTC (a calendar value by spec)."""
    elapsed = datetime.datetime.now(datetime.timezone.utc) - SIGNING_EPOCH
    return int(elapsed.total_seconds() * 100_000)


class VehicleLink:
    """One MAVLink instance: socket, target address (latched on the first peer), codec."""

    def __init__(self, name: str, bind: Endpoint, target: Endpoint | None, sysid: int, compid: int,
                 signing_key: bytes | None = None) -> None:
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
        self.mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.mav.robust_parsing = True
        if signing_key is not None:
            self._setup_signing(signing_key)

    @property
    def port(self) -> int:
        return int(self.sock.getsockname()[1])

    def _setup_signing(self, key: bytes) -> None:
        signing = self.mav.signing
        signing.secret_key = bytes(key)
        signing.sign_outgoing = True
        signing.link_id = 0
        signing.timestamp = signing_timestamp_now()
        allow: Callable[[Any, int], bool] = lambda _mav, msg_id: msg_id in UNSIGNED_ALLOWED_IDS
        signing.allow_unsigned_callback = allow

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
        leftover = len(mav.buf) - mav.buf_index
        mav.buf, mav.buf_index = bytearray(), 0
        mav.expected_length = mavlink.HEADER_LEN_V1 + 2
        return messages, leftover

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

    def close(self) -> None:
        self.sock.close()
