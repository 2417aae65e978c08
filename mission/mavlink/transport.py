"""Link URLs and the transports they name: bytes in and out, nothing MAVLink-specific.

URL forms (pymavlink's and MAVSDK's): ``udpin:HOST:PORT`` (bind and listen; the vehicle talks
first; ``udp:`` is the same), ``udpout:HOST:PORT`` (send to), ``tcp:HOST:PORT`` (connect), each
also with ``://``; ``HOST:PORT`` alone takes a default scheme; an empty host (``:14540``) is
127.0.0.1; a serial device ``/dev/ttyACM0[:BAUD]``, ``serial:/dev/ttyACM0[:BAUD]`` or ``COM3``
(57600 baud by default).
"""
from __future__ import annotations

import errno
import select
import socket
import threading
from dataclasses import dataclass
from typing import Any, Protocol

from mission.errors import LinkError, LinkPortInUse, PortInUse
from mission.port_holder import is_addr_in_use, port_in_use

Address = tuple[str, int]
DEFAULT_BAUD = 57600
_NETWORK_SCHEMES = ("udpin", "udpout", "udp", "tcp")


@dataclass(frozen=True)
class Endpoint:
    """A parsed link URL: ``scheme`` is ``udpin``, ``udpout``, ``tcp`` or ``serial``; ``host`` and
    ``port`` for the network ones, ``device`` and ``baud`` for serial."""

    scheme: str
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = DEFAULT_BAUD

    @property
    def address(self) -> Address:
        return self.host, self.port

    def __str__(self) -> str:
        if self.scheme == "serial":
            return f"serial:{self.device}:{self.baud}"
        return f"{self.scheme}:{self.host}:{self.port}"


def parse_url(url: str, default_scheme: str | None = None) -> Endpoint:
    """Parse a link URL (forms in the module docstring). ``default_scheme`` (``udpin`` or
    ``udpout``) is taken by a bare ``HOST:PORT``; without one a bare address is refused.
    Raises ``ValueError`` naming the URL and what is wrong."""
    text = url.strip()
    scheme, rest = None, text
    for candidate in _NETWORK_SCHEMES + ("serial",):
        for sep in ("://", ":"):
            if text.startswith(candidate + sep):
                scheme, rest = candidate, text[len(candidate) + len(sep):]
                break
        if scheme is not None:
            break
    if scheme == "serial" or (scheme is None and (text.startswith("/") or text.upper().startswith("COM"))):
        device, _, baud = rest.replace(",", ":").partition(":")
        if not device:
            raise ValueError(f"link url {url!r}: no serial device")
        if baud and not baud.isdigit():
            raise ValueError(f"link url {url!r}: baud rate {baud!r} is not an integer")
        return Endpoint("serial", device=device, baud=int(baud) if baud else DEFAULT_BAUD)
    if scheme is None:
        if default_scheme is None:
            raise ValueError(f"link url {url!r}: expected udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT "
                             "or a serial device")
        scheme = default_scheme
    scheme = "udpin" if scheme == "udp" else scheme
    host, sep, port = rest.rpartition(":")
    if not sep or ":" in host or "/" in host:
        raise ValueError(f"link url {url!r}: expected {scheme}:HOST:PORT")
    if not port.isdigit():
        raise ValueError(f"link url {url!r}: port {port!r} is not an integer")
    if not 0 <= int(port) <= 65535:
        raise ValueError(f"link url {url!r}: port {int(port)} out of range")
    return Endpoint(scheme, host or "127.0.0.1", int(port))


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
        from mission.mavlink_env import mavutil

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
