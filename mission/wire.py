"""Wire formats of the carrier-passenger bus (pure: no Zenoh, no sockets).

Two robots talk over Zenoh: the carrier publishes its state, the passenger publishes its mission
phase and state. This module defines those messages, their codecs and their validation; the
transport (:mod:`mission.carrier_bridge`) only moves bytes.

Carrier state, JSON (the default encoding), one UTF-8 object per sample::

    {"stamp": 12.345,            # [s] sender's clock (any monotonic epoch; only its order is used)
     "seq": 7,                   # integer >= 0, strictly increasing per sender
     "frame": "local_ned",       # "local_ned" or "wgs84"
     "position": [n, e, d],      # local_ned: [m] north, east, down in the vehicle's local frame
                                 # wgs84: [lat deg, lon deg, alt m (AMSL, up)]
     "velocity": [vn, ve, vd],   # [m/s] NED, whatever the position frame
     "yaw": 0.1}                 # [rad] heading from north towards east; optional, may be null

Every number must be finite; ``position``/``velocity`` have exactly 3 numbers, each within
+-1e7 m and +-1e3 m/s (:data:`POSITION_LIMIT_M`, :data:`VELOCITY_LIMIT_M_S`: "range" beyond);
``seq`` fits an int64; unknown fields are ignored (forward compatibility). A ``wgs84`` state is
converted to local NED through the vehicle's origin (PX4's GPS_GLOBAL_ORIGIN) with
:func:`geodetic_to_ned`.

Carrier state as ROS 2 ``nav_msgs/msg/Odometry`` in CDR (``encoding = "cdr"``): see
:mod:`mission.wire_ros2`, which also has the Twist of a ROS 2 carrier's velocity command.

Passenger status, JSON::

    {"phase": "RIDING", "stamp": 3.2, "seq": 41,
     "position": [n, e, d], "velocity": [vn, ve, vd],     # [m], [m/s] local NED
     "separated": false, "anchor": [n, e, d] | null}      # latched anchor [m] NED after separation

A decode or validation failure raises :class:`WireError` whose ``reason`` is one of
:data:`REASONS`; the bridge counts drops per reason.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from mission import geodesy
from mission.errors import MarsupialError

Frame = Literal["local_ned", "wgs84"]
FRAMES: tuple[str, ...] = ("local_ned", "wgs84")

#: Mission phases the controller publishes, in mission order (ABORT can follow any).
PHASES: tuple[str, ...] = (
    "PREFLIGHT", "STREAMING", "ARMING", "OFFBOARD", "JOIN", "RIDING", "SEPARATED", "NAVIGATING",
    "ARRIVED", "HOLD", "LAND", "DONE", "ABORT",
)

#: Reasons a sample is rejected (keys of the bridge's drop counters). ``size`` is checked by the
#: bridge before decoding; ``stale_seq`` and ``stale_stamp`` come from its ordering check, the
#: carrier feed's binding and plausibility gate add ``unbound``, ``source``, ``seq_jump``,
#: ``stamp_jump``, ``speed``, ``jump``, ``velocity`` and ``gap`` (:mod:`mission.feed_gate`), and
#: ``internal`` comes from a bug in a decoder, not from the codecs.
REASONS: tuple[str, ...] = (
    "size", "decode", "missing", "type", "shape", "nonfinite", "frame", "range", "orientation", "phase",
    "origin", "stale_seq", "stale_stamp", "unbound", "source", "seq_jump", "stamp_jump", "speed", "jump",
    "velocity", "gap", "internal",
)

SEQ_MAX = 2**63 - 1  # sequence numbers are int64, as in ROS 2 / DDS
POSITION_LIMIT_M = 1e7  # |local NED component| or |wgs84 altitude| [m]: beyond this a sample is corrupt
VELOCITY_LIMIT_M_S = 1e3  # |velocity component| [m/s]



class WireError(MarsupialError):
    """A sample could not be decoded or failed validation. ``reason`` is one of :data:`REASONS`."""

    def __init__(self, reason: str, detail: str = "") -> None:
        self.reason, self.detail = reason, detail
        super().__init__(f"{reason}: {detail}" if detail else reason)


# --------------------------------------------------------------------------- values


def _vec3(value: Any, name: str) -> np.ndarray:
    """A read-only float array (3,) from a sequence of 3 real numbers (not bools)."""
    if isinstance(value, np.ndarray):
        if value.shape != (3,):
            raise WireError("shape", f"{name} must have 3 components, got shape {value.shape}")
        if not np.issubdtype(value.dtype, np.number) or np.issubdtype(value.dtype, np.bool_):
            raise WireError("type", f"{name} must be numbers")
        out = value.astype(float)
    else:
        if not isinstance(value, (list, tuple)):
            raise WireError("type", f"{name} must be a list of 3 numbers, got {type(value).__name__}")
        if len(value) != 3:
            raise WireError("shape", f"{name} must have 3 components, got {len(value)}")
        for v in value:
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise WireError("type", f"{name} must be numbers, got {type(v).__name__}")
        try:
            out = np.array(value, dtype=float)
        except OverflowError:
            raise WireError("nonfinite", f"{name} overflows a float") from None
    if not np.all(np.isfinite(out)):
        raise WireError("nonfinite", f"{name} = {out.tolist()}")
    out.flags.writeable = False
    return out


def _real(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise WireError("type", f"{name} must be a number, got {type(value).__name__}")
    try:
        out = float(value)
    except OverflowError:
        raise WireError("nonfinite", f"{name} overflows a float") from None
    if not math.isfinite(out):
        raise WireError("nonfinite", f"{name} = {out}")
    return out


def _int(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise WireError("type", f"{name} must be an integer, got {type(value).__name__}")
    if not 0 <= value <= SEQ_MAX:
        raise WireError("range", f"{name} must be in 0..2**63-1, got {value}")
    return int(value)


def _bounded(v: np.ndarray, limit: float, name: str) -> np.ndarray:
    """``v`` if every component is within +-``limit``; a finite but absurd number (a carrier
    10 000 km away, or a sequence number that would make every later one look old) is a
    corrupt sample, not a state."""
    if np.any(np.abs(v) > limit):
        raise WireError("range", f"{name} = {v.tolist()}: components must be within +-{limit:g}")
    return v


def wrap_pi(angle_rad: float) -> float:
    """Angle wrapped to (-pi, pi] [rad]."""
    a = math.remainder(angle_rad, 2 * math.pi)
    return math.pi if a == -math.pi else a


@dataclass(frozen=True)
class CarrierState:
    """The carrier's state as sent on the wire (validated on construction).

    stamp_s [s] sender's clock; seq (>= 0) per-sender sequence number; frame "local_ned" or
    "wgs84"; position: local_ned [m] (n, e, d), wgs84 (lat [deg], lon [deg], alt [m] AMSL up);
    velocity_ned_m_s [m/s] NED in both frames; yaw_rad [rad] heading from north towards east, or
    None. Arrays are read-only float (3,). Raises :class:`WireError` when invalid.
    """

    stamp_s: float
    seq: int
    frame: Frame
    position: np.ndarray
    velocity_ned_m_s: np.ndarray
    yaw_rad: float | None = None

    def __post_init__(self) -> None:
        if self.frame not in FRAMES:
            raise WireError("frame", f"unknown frame {self.frame!r} (expected one of {FRAMES})")
        object.__setattr__(self, "stamp_s", _real(self.stamp_s, "stamp"))
        object.__setattr__(self, "seq", _int(self.seq, "seq"))
        object.__setattr__(self, "position", _bounded(_vec3(self.position, "position"), POSITION_LIMIT_M, "position"))
        object.__setattr__(self, "velocity_ned_m_s", _bounded(_vec3(self.velocity_ned_m_s, "velocity"),
                                                              VELOCITY_LIMIT_M_S, "velocity"))
        if self.yaw_rad is not None:
            object.__setattr__(self, "yaw_rad", _real(self.yaw_rad, "yaw"))
        if self.frame == "wgs84":
            lat, lon, _ = self.position
            if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
                raise WireError("range", f"wgs84 lat/lon out of range: {lat}, {lon}")


@dataclass(frozen=True)
class PassengerStatus:
    """The passenger's mission phase and state (validated on construction).

    phase one of :data:`PHASES`; stamp_s [s] sender's clock; seq (>= 0); position_ned_m [m] and
    velocity_ned_m_s [m/s] local NED; separated: the separation latch has fired; anchor_ned_m
    [m] the latched anchor (carrier position at separation) or None.
    """

    phase: str
    stamp_s: float
    seq: int
    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    separated: bool = False
    anchor_ned_m: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.phase, str):
            raise WireError("type", f"phase must be a string, got {type(self.phase).__name__}")
        if self.phase not in PHASES:
            raise WireError("phase", f"unknown phase {self.phase!r}")
        if not isinstance(self.separated, (bool, np.bool_)):
            raise WireError("type", f"separated must be a boolean, got {type(self.separated).__name__}")
        object.__setattr__(self, "separated", bool(self.separated))
        object.__setattr__(self, "stamp_s", _real(self.stamp_s, "stamp"))
        object.__setattr__(self, "seq", _int(self.seq, "seq"))
        object.__setattr__(self, "position_ned_m", _bounded(_vec3(self.position_ned_m, "position"), POSITION_LIMIT_M,
                                                            "position"))
        object.__setattr__(self, "velocity_ned_m_s", _bounded(_vec3(self.velocity_ned_m_s, "velocity"),
                                                              VELOCITY_LIMIT_M_S, "velocity"))
        if self.anchor_ned_m is not None:
            object.__setattr__(self, "anchor_ned_m", _bounded(_vec3(self.anchor_ned_m, "anchor"), POSITION_LIMIT_M,
                                                              "anchor"))


# --------------------------------------------------------------------------- geodesy


@dataclass(frozen=True)
class GeoOrigin:
    """Origin of the local NED frame: lat [deg], lon [deg], alt [m] AMSL (PX4's GPS_GLOBAL_ORIGIN)."""

    lat_deg: float
    lon_deg: float
    alt_m: float

    def __post_init__(self) -> None:
        for name in ("lat_deg", "lon_deg", "alt_m"):
            if not math.isfinite(getattr(self, name)):
                raise WireError("origin", f"origin {name} must be finite")
        if not (-90.0 < self.lat_deg < 90.0 and -180.0 <= self.lon_deg <= 180.0):
            raise WireError("origin", f"origin out of range: {self.lat_deg}, {self.lon_deg}")


def geodetic_to_ned(lat_deg: float, lon_deg: float, alt_m: float, origin: GeoOrigin) -> np.ndarray:
    """Local NED [m] (3,) of a geodetic point, relative to ``origin``: PX4's projection
    (:func:`mission.geodesy.project`); down = origin altitude minus altitude."""
    north, east = geodesy.project(lat_deg, lon_deg, origin.lat_deg, origin.lon_deg)
    return np.array([north, east, origin.alt_m - alt_m])


def ned_to_geodetic(ned_m: np.ndarray, origin: GeoOrigin) -> tuple[float, float, float]:
    """Inverse of :func:`geodetic_to_ned`: (lat [deg], lon [deg], alt [m]) of a local NED point [m]."""
    north, east, down = (float(v) for v in ned_m)
    lat, lon = geodesy.reproject(north, east, origin.lat_deg, origin.lon_deg)
    return lat, lon, origin.alt_m - down


def to_local_ned(state: CarrierState, origin: GeoOrigin | None) -> CarrierState:
    """``state`` in frame local_ned: unchanged if already so; a wgs84 state is projected through
    ``origin`` (raises ``WireError("origin")`` if there is none)."""
    if state.frame == "local_ned":
        return state
    if origin is None:
        raise WireError("origin", "a wgs84 carrier state needs the vehicle's origin (GPS_GLOBAL_ORIGIN)")
    ned = geodetic_to_ned(*(float(v) for v in state.position), origin)
    return CarrierState(state.stamp_s, state.seq, "local_ned", ned, state.velocity_ned_m_s, state.yaw_rad)


# --------------------------------------------------------------------------- JSON


def _load_object(raw: bytes | bytearray | memoryview | str) -> dict[str, Any]:
    try:
        text = raw if isinstance(raw, str) else bytes(raw).decode("utf-8")
        obj = json.loads(text)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise WireError("decode", f"not UTF-8 JSON: {exc}") from None
    if not isinstance(obj, dict):
        raise WireError("decode", f"expected a JSON object, got {type(obj).__name__}")
    return obj


def _field(obj: dict[str, Any], name: str) -> Any:
    if name not in obj:
        raise WireError("missing", f"field {name!r} missing")
    return obj[name]


def encode_carrier_json(state: CarrierState) -> bytes:
    """The JSON bytes of ``state`` (schema in the module docstring)."""
    return json.dumps({
        "stamp": state.stamp_s,
        "seq": state.seq,
        "frame": state.frame,
        "position": state.position.tolist(),
        "velocity": state.velocity_ned_m_s.tolist(),
        "yaw": state.yaw_rad,
    }, allow_nan=False).encode()


def decode_carrier_json(raw: bytes | bytearray | memoryview | str) -> CarrierState:
    """A validated :class:`CarrierState` from JSON bytes; raises :class:`WireError`.

    JSON's non-standard ``NaN``/``Infinity`` literals are parsed, then rejected as "nonfinite".
    """
    obj = _load_object(raw)
    frame = _field(obj, "frame")
    if not isinstance(frame, str):
        raise WireError("type", f"frame must be a string, got {type(frame).__name__}")
    return CarrierState(
        stamp_s=_field(obj, "stamp"),
        seq=_field(obj, "seq"),
        frame=frame,  # type: ignore[arg-type]  # validated by CarrierState
        position=_field(obj, "position"),
        velocity_ned_m_s=_field(obj, "velocity"),
        yaw_rad=obj.get("yaw"),
    )


def encode_passenger_json(status: PassengerStatus) -> bytes:
    """The JSON bytes of ``status`` (schema in the module docstring)."""
    return json.dumps({
        "phase": status.phase,
        "stamp": status.stamp_s,
        "seq": status.seq,
        "position": status.position_ned_m.tolist(),
        "velocity": status.velocity_ned_m_s.tolist(),
        "separated": status.separated,
        "anchor": None if status.anchor_ned_m is None else status.anchor_ned_m.tolist(),
    }, allow_nan=False).encode()


def decode_passenger_json(raw: bytes | bytearray | memoryview | str) -> PassengerStatus:
    """A validated :class:`PassengerStatus` from JSON bytes; raises :class:`WireError`."""
    obj = _load_object(raw)
    return PassengerStatus(
        phase=_field(obj, "phase"),
        stamp_s=_field(obj, "stamp"),
        seq=_field(obj, "seq"),
        position_ned_m=_field(obj, "position"),
        velocity_ned_m_s=_field(obj, "velocity"),
        separated=_field(obj, "separated"),
        anchor_ned_m=obj.get("anchor"),
    )


def decode_carrier(raw: bytes | bytearray | memoryview, encoding: str, *, seq: int = 0) -> CarrierState:
    """Dispatch on ``encoding`` ("json" or "cdr"); ``seq`` is used by CDR only."""
    if encoding == "json":
        return decode_carrier_json(raw)
    if encoding == "cdr":
        from mission.wire_ros2 import decode_odometry_cdr  # it imports this module

        return decode_odometry_cdr(raw, seq=seq)
    raise ValueError(f"unknown encoding {encoding!r}")


def encode_carrier(state: CarrierState, encoding: str) -> bytes:
    """Dispatch on ``encoding`` ("json" or "cdr")."""
    if encoding == "json":
        return encode_carrier_json(state)
    if encoding == "cdr":
        from mission.wire_ros2 import encode_odometry_cdr  # it imports this module

        return encode_odometry_cdr(state)
    raise ValueError(f"unknown encoding {encoding!r}")
