"""Link URLs (pure: parsing only, no socket), the forms pymavlink and MAVSDK use.

``udpin:HOST:PORT`` (bind and listen; the vehicle talks first; ``udp:`` is the same),
``udpout:HOST:PORT`` (send to), ``tcp:HOST:PORT`` (connect), each also with ``://``;
``HOST:PORT`` alone takes a default scheme; an empty host (``:14540``) is 127.0.0.1; a serial
device ``/dev/ttyACM0[:BAUD]``, ``serial:/dev/ttyACM0[:BAUD]`` or ``COM3`` (57600 baud by
default). The configuration checks them (:mod:`mission.config.fields`), the transports that open
them (:mod:`mission.mavlink.transport`) and the mock vehicle read them with this one parser.
"""
from __future__ import annotations

from dataclasses import dataclass

Address = tuple[str, int]
#: The vehicle's endpoint by default (``mavlink.url``): PX4 SITL's onboard link, which sends to
#: UDP 14540 on the local host.
DEFAULT_URL = "udpin:127.0.0.1:14540"
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
