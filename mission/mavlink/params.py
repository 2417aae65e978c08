"""PX4 parameters over MAVLink: the wire encoding, and reading or writing one on a link.

PX4 sends an INT32 parameter's bits in PARAM_VALUE's float field (the "bytewise" encoding:
reinterpreted, never converted) and expects them so in PARAM_SET; a REAL32 travels as the float
(as a PX4 SITL does, ../shared/REFERENCE.md). :class:`ParamClient` reads a parameter
(PARAM_REQUEST_READ, answered by PARAM_VALUE) and writes one (PARAM_SET, confirmed by the
PARAM_VALUE PX4 sends back with the value it kept), each attempt waiting on the session's clock.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

from mission.errors import LinkError, LinkTimeout
from mission.mavlink.env import mavlink

if TYPE_CHECKING:
    from mission.mavlink.session import LinkSession

REAL32 = mavlink.MAV_PARAM_TYPE_REAL32
INT32 = mavlink.MAV_PARAM_TYPE_INT32


def pack_int32(value: int) -> float:
    """The float32 whose bits are the int32 ``value`` (PX4's bytewise PARAM_VALUE encoding)."""
    return struct.unpack("<f", struct.pack("<i", int(value)))[0]


def unpack_int32(encoded: float) -> int:
    """Inverse of :func:`pack_int32`."""
    return struct.unpack("<i", struct.pack("<f", encoded))[0]


def decode(wire_value: float, param_type: int) -> float:
    """A PARAM_VALUE's value: integer types unpacked from the float's bits, REAL32 as it is."""
    return wire_value if param_type == REAL32 else float(unpack_int32(wire_value))


def encode(value: float, param_type: int) -> float:
    """PARAM_SET's float field for ``value`` of ``param_type`` (integers rounded, then packed)."""
    return float(value) if param_type == REAL32 else pack_int32(int(round(value)))


@dataclass(frozen=True)
class ParamValue:
    """A parameter as the vehicle last reported it: name, value (decoded), MAV_PARAM_TYPE, and
    the clock time it arrived [s]."""

    name: str
    value: float
    param_type: int
    rx_s: float


def received(msg: Any, t_rx: float) -> ParamValue:
    """The :class:`ParamValue` of a PARAM_VALUE received at ``t_rx`` [s]."""
    return ParamValue(str(msg.param_id), decode(float(msg.param_value), int(msg.param_type)), int(msg.param_type), t_rx)


class ParamClient:
    """Reads and writes one parameter at a time on ``session`` (which keeps every PARAM_VALUE
    from the vehicle in ``session.params``); ``send(msg, counter)`` sends, ``require_vehicle()``
    returns the identified (system, component) or raises LinkError."""

    def __init__(self, session: LinkSession, send: Callable[[Any, str | None], bool],
                 require_vehicle: Callable[[], tuple[int, int]]) -> None:
        self.session, self.send, self.require_vehicle = session, send, require_vehicle

    def get(self, name: str, timeout_s: float = 0.5, retries: int = 3) -> ParamValue:
        """The vehicle's ``name`` (PARAM_REQUEST_READ); LinkTimeout if it never answers (PX4 does not
        answer for a name it does not have)."""
        target = self.require_vehicle()
        request = mavlink.MAVLink_param_request_read_message(target[0], target[1], name.encode("ascii"), -1)
        return self._exchange(name, request, lambda pv: True, timeout_s, retries)

    def set(self, name: str, value: float, timeout_s: float = 0.5, retries: int = 3) -> ParamValue:
        """Set ``name`` to ``value`` (its type read first if not yet known) and confirm it by the
        PARAM_VALUE that follows; LinkError if the vehicle keeps another value."""
        if not math.isfinite(value):
            raise ValueError(f"{name}: value must be finite, got {value!r}")
        with self.session.lock:
            known = self.session.params.get(name)
        param_type = (known or self.get(name, timeout_s, retries)).param_type
        target = self.require_vehicle()
        wanted = decode(encode(value, param_type), param_type)
        msg = mavlink.MAVLink_param_set_message(target[0], target[1], name.encode("ascii"), encode(value, param_type),
                                                param_type)
        kept = self._exchange(name, msg, lambda pv: True, timeout_s, retries)
        if not math.isclose(kept.value, wanted, rel_tol=1e-6, abs_tol=1e-9):
            raise LinkError(f"vehicle kept {name} = {kept.value:g} (asked {value:g})")
        return kept

    def _exchange(self, name: str, msg: Any, accept: Callable[[ParamValue], bool], timeout_s: float,
                  retries: int) -> ParamValue:
        """Send ``msg`` until a PARAM_VALUE of ``name`` arrives after it (``retries`` resends,
        ``timeout_s`` [s of clock] each)."""
        s = self.session
        for _ in range(retries + 1):
            t_sent = s.clock.now()
            self.send(msg, None)
            deadline = t_sent + timeout_s
            with s.changed:
                while True:
                    pv = s.params.get(name)
                    if pv is not None and pv.rx_s >= t_sent and accept(pv):
                        return pv
                    if s.closed or not s.wait_locked(deadline):
                        break
        raise LinkTimeout(f"no PARAM_VALUE {name} after {retries + 1} attempts of {timeout_s:g} s")
