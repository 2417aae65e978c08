"""The transports a link URL names (:mod:`mission.config.urls`): UDP listen/send, TCP and
serial, bytes in and out, nothing MAVLink-specific; and :class:`Tlog`, the bytes' log as
QGroundControl and ``mavlogdump.py`` read it (a ``.tlog``: each packet prefixed by an 8-byte
big-endian microsecond timestamp, wall time from the injected clock and an epoch taken at open).
"""
from __future__ import annotations

import errno
import select
import socket
import struct
import threading
import time
from pathlib import Path
from typing import IO, Any, Protocol

from mission.errors import LinkError, LinkPortInUse, PortInUse
from mission.config.urls import Address, parse_url
from mission.port_holder import is_addr_in_use, port_in_use
from mission.time.clock import Clock


class Transport(Protocol):
    """Bytes to and from the vehicle."""

    datagram: bool
    """True if every read is one whole datagram (the parser is reset after each)."""

    def read(self, timeout_wall_s: float) -> tuple[bytes, Address | None]:
        """Up to one datagram or chunk, and who sent it; ``b""`` after ``timeout_wall_s``."""
        ...

    def write(self, buf: bytes) -> bool:
        """Send; False while there is nobody to send to (udpin before the vehicle spoke)."""
        ...

    def set_peer(self, address: Address) -> None:
        """The vehicle spoke from ``address``: answer there (udpin only)."""
        ...

    def local_port(self) -> int | None: ...

    def close(self) -> None: ...


class UdpTransport:
    """UDP socket. ``listen``: bind HOST:PORT and answer the latest vehicle address;
    otherwise send to HOST:PORT from an ephemeral port."""

    datagram = True

    def __init__(self, host: str, port: int, listen: bool) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            if listen:
                self._sock.bind((host, port))
                self._peer: Address | None = None
            else:
                self._peer = (socket.gethostbyname(host), port)
                self._sock.bind(("0.0.0.0", 0))
        except OSError as exc:
            self._sock.close()
            if listen and is_addr_in_use(exc):
                raise port_in_use(f"MAVLink link udpin:{host}:{port}", host, port, cls=LinkPortInUse) from None
            raise
        self._listen = listen

    def read(self, timeout_wall_s: float) -> tuple[bytes, Address | None]:
        ready, _, _ = select.select([self._sock], [], [], timeout_wall_s)
        if not ready:
            return b"", None
        try:
            data, address = self._sock.recvfrom(65535)
        except OSError as exc:
            if exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK, errno.ECONNREFUSED):
                return b"", None
            raise
        return data, address

    def write(self, buf: bytes) -> bool:
        peer = self._peer
        if peer is None:
            return False
        self._sock.sendto(buf, peer)
        return True

    def set_peer(self, address: Address) -> None:
        if self._listen:
            self._peer = address

    def local_port(self) -> int | None:
        return int(self._sock.getsockname()[1])

    def close(self) -> None:
        self._sock.close()


class TcpTransport:
    """TCP client connection to HOST:PORT (a byte stream)."""

    datagram = False

    def __init__(self, host: str, port: int, connect_timeout_s: float = 3.0) -> None:
        self._sock = socket.create_connection((host, port), timeout=connect_timeout_s)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock.settimeout(None)
        self._address: Address = (host, port)
        self._write_lock = threading.Lock()

    def read(self, timeout_wall_s: float) -> tuple[bytes, Address | None]:
        ready, _, _ = select.select([self._sock], [], [], timeout_wall_s)
        if not ready:
            return b"", None
        data = self._sock.recv(65535)
        if not data:
            raise ConnectionResetError(errno.ECONNRESET, "TCP peer closed the connection")
        return data, self._address

    def write(self, buf: bytes) -> bool:
        with self._write_lock:
            self._sock.sendall(buf)
        return True

    def set_peer(self, address: Address) -> None:
        return None

    def local_port(self) -> int | None:
        return int(self._sock.getsockname()[1])

    def close(self) -> None:
        self._sock.close()


class SerialTransport:
    """Serial device through pymavlink's ``mavserial`` (a byte stream)."""

    datagram = False

    def __init__(self, device: str, baud: int) -> None:
        from mission.mavlink.env import mavutil

        self._conn: Any = mavutil.mavlink_connection(device, baud=baud, autoreconnect=False)

    def read(self, timeout_wall_s: float) -> tuple[bytes, Address | None]:
        if not self._conn.select(timeout_wall_s):
            return b"", None
        data = self._conn.recv(4096)
        return (data.encode("latin-1") if isinstance(data, str) else bytes(data)), None

    def write(self, buf: bytes) -> bool:
        self._conn.write(buf)
        return True

    def set_peer(self, address: Address) -> None:
        return None

    def local_port(self) -> int | None:
        return None

    def close(self) -> None:
        self._conn.close()


def open_transport(url: str) -> Transport:
    """Open the transport a URL names; a bad URL and foreign errors become :class:`LinkError`
    (a busy udpin port: :class:`~mission.errors.LinkPortInUse`, naming its holder)."""
    try:
        endpoint = parse_url(url)
    except ValueError as exc:
        raise LinkError(str(exc)) from None
    try:
        if endpoint.scheme == "udpin":
            return UdpTransport(endpoint.host, endpoint.port, listen=True)
        if endpoint.scheme == "udpout":
            return UdpTransport(endpoint.host, endpoint.port, listen=False)
        if endpoint.scheme == "tcp":
            return TcpTransport(endpoint.host, endpoint.port)
        return SerialTransport(endpoint.device, endpoint.baud)
    except (LinkError, PortInUse):
        raise
    except Exception as exc:  # OSError, serial.SerialException and other foreign errors
        raise LinkError(f"cannot open MAVLink link {url!r}: {exc}") from exc


class Tlog:
    """Appends packets to ``path`` (thread-safe); :meth:`close` is idempotent."""

    def __init__(self, path: str | Path, clock: Clock) -> None:
        self.path, self._clock = Path(path), clock
        self._file: IO[bytes] | None = open(self.path, "wb")
        self._epoch_us = time.time_ns() // 1000 - int(clock.now() * 1e6)
        self._lock = threading.Lock()

    def write(self, packet: bytes | bytearray) -> None:
        with self._lock:
            if self._file is None:
                return
            usec = (self._epoch_us + int(self._clock.now() * 1e6)) & ~3
            self._file.write(struct.pack(">Q", usec) + bytes(packet))

    def flush(self) -> None:
        with self._lock:
            if self._file is not None:
                self._file.flush()

    def close(self) -> None:
        with self._lock:
            file, self._file = self._file, None
        if file is not None:
            file.close()
