"""The building blocks of the configuration schema (:mod:`mission.config.schema`): the strict base
model of every section, bounded field types, and the syntax checks of strings a user types
(MAVLink URLs, ports, Zenoh endpoints and key expressions, printable names). Each check raises
``ValueError`` saying what is wrong; pydantic names the field.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Annotated, Any

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field

from mission.config.urls import parse_url


class Section(BaseModel):
    """Base of every configuration section."""

    # strict: "3" and true are not numbers, 2.5 is not an integer (an int is still a float)
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, strict=True)


MAX_PATH_CHARS = 1024
MAX_URL_CHARS = 256
COORD_LIMIT_M = 1e6  # |component| of a position in the config [m]


def _tuple_of_list(value: Any) -> Any:
    """TOML has no tuples: a list is taken as one (its items stay strictly typed)."""
    return tuple(value) if isinstance(value, list) else value


FloatPair = Annotated[tuple[float, float], BeforeValidator(_tuple_of_list)]
Coord = Annotated[float, Field(ge=-COORD_LIMIT_M, le=COORD_LIMIT_M)]
Path_ = Annotated[str, Field(min_length=1, max_length=MAX_PATH_CHARS)]


def printable(value: str) -> str:
    """``value`` if it has no control characters."""
    if any(ord(ch) < 32 or ord(ch) == 127 for ch in value):
        raise ValueError("must not contain control characters")
    return value


_ZENOH_ENDPOINT = re.compile(r"^(?P<proto>[a-z][a-z0-9-]*)/(?P<address>[^#?\s]+?)(?P<rest>[#?].*)?$")
_HOST_PORT_PROTOCOLS = {"tcp", "udp", "tls", "quic", "ws"}


def check_port(text: str, *, allow_zero: bool) -> int:
    """A port number 1..65535 (0 too if ``allow_zero``: an ephemeral listener); ValueError otherwise."""
    if not text.isdigit():
        raise ValueError(f"port {text!r} is not a number")
    port = int(text)
    if not (0 if allow_zero else 1) <= port <= 65535:
        raise ValueError(f"port {port} out of range {0 if allow_zero else 1}..65535")
    return port


def _host_port(spec: str, *, allow_zero: bool) -> tuple[str, int]:
    host, sep, port = spec.rpartition(":")
    if not sep or not host or host in ("[]",):
        raise ValueError("expected HOST:PORT")
    return host, check_port(port, allow_zero=allow_zero)


@dataclass(frozen=True)
class ZenohEndpoint:
    """A parsed Zenoh locator ``PROTO/ADDRESS[?|#config]``: ``host`` and ``port`` for the
    protocols whose address is ``HOST:PORT`` (tcp, udp, tls, quic, ws), else ``""`` and None."""

    proto: str
    address: str
    host: str = ""
    port: int | None = None


def parse_zenoh_endpoint(endpoint: str, *, listen: bool) -> ZenohEndpoint:
    """The parts of a Zenoh endpoint (port 0, an ephemeral port, only if ``listen``); ValueError
    naming what is wrong."""
    m = _ZENOH_ENDPOINT.match(endpoint)
    if m is None:
        raise ValueError("expected a Zenoh endpoint PROTO/ADDRESS, e.g. tcp/127.0.0.1:7447")
    if m["proto"] not in _HOST_PORT_PROTOCOLS:
        return ZenohEndpoint(m["proto"], m["address"])
    host, port = _host_port(m["address"], allow_zero=listen)
    return ZenohEndpoint(m["proto"], m["address"], host, port)


def check_mavlink_url(url: str) -> str:
    """A link URL as the link reads it (:func:`mission.config.urls.parse_url`: ``udpin:``,
    ``udp:``, ``udpout:``, ``tcp:HOST:PORT`` or a serial device ``/dev/X[:BAUD]``,
    ``serial:/dev/X[:BAUD]``, ``COMn[:BAUD]``), and one that can work: port 0 (ephemeral) only to
    listen on, a baud rate in 50..10000000. ValueError naming what is wrong."""
    endpoint = parse_url(url)
    if endpoint.scheme == "serial" and not 50 <= endpoint.baud <= 10_000_000:
        raise ValueError(f"baud rate {endpoint.baud} must be in 50..10000000")
    if endpoint.scheme in ("udpout", "tcp") and endpoint.port == 0:
        raise ValueError(f"port 0 is only for listening (udpin:); {endpoint.scheme}: needs the peer's port")
    return url


def check_zenoh_endpoint(endpoint: str, *, listen: bool) -> str:
    """``endpoint`` if :func:`parse_zenoh_endpoint` takes it; ValueError otherwise."""
    parse_zenoh_endpoint(endpoint, listen=listen)
    return endpoint


def check_key_expr(key: str) -> str:
    """A Zenoh key expression (Zenoh's own parser decides); ValueError otherwise."""
    import zenoh

    try:
        zenoh.KeyExpr(key)
    except zenoh.ZError as exc:
        raise ValueError(f"not a Zenoh key expression: {exc}") from None
    return key
