"""Wire formats of the carrier-passenger bus (pure: no Zenoh, no sockets).

The carrier publishes its state (:class:`CarrierState`: ``stamp`` [s] on the sender's clock,
``seq`` strictly increasing per sender, ``frame`` ``"local_ned"`` or ``"wgs84"``, ``position``
[m] NED or [deg, deg, m AMSL], ``velocity`` [m/s] NED, optional ``yaw`` [rad] from north and
``acceleration`` [m/s^2] NED), the passenger its status (:class:`PassengerStatus`: phase, stamp,
seq, position [m] and velocity [m/s] NED, ``separated``, the latched ``anchor`` [m] NED, in
ABORT the ``reason``, and ``holding``: it holds on the dock point it had, its carrier feed not
trusted, so the carrier pauses). Both are pydantic models parsed and validated from JSON in one
pass; unknown fields are ignored.
Invariants: every number finite, vectors of exactly 3 within :data:`POSITION_LIMIT_M`,
:data:`VELOCITY_LIMIT_M_S` and :data:`ACCELERATION_LIMIT_M_S2`, ``seq`` an int64. A failure raises
:class:`WireError` whose ``reason`` is one of :data:`REASONS` (:func:`wire_error` maps pydantic's
error types). A ``wgs84`` state is converted to local NED through the vehicle's origin with
:func:`geodetic_to_ned`. The CDR (ROS 2) codecs are in :mod:`mission.bus.ros2`, the choice
between the two by ``zenoh.encoding`` in :mod:`mission.bus.encodings`. The JSON layout with an
example: docs/wire.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar, Literal, get_args

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError, model_validator
from pydantic_core import PydanticCustomError, core_schema

from mission.core import geodesy
from mission.phases.phase import Phase
from mission.errors import MarsupialError

Frame = Literal["local_ned", "wgs84"]
FRAMES: tuple[str, ...] = get_args(Frame)

#: Reasons a sample is rejected (keys of the bridge's drop counters). ``size`` is checked by the
#: bridge before decoding, then, with a signing key, ``unsigned``, ``signature``, ``replay`` and
#: ``contest`` (:mod:`mission.bus.signing`; a contested passenger binding too); ``stale_seq`` and
#: ``stale_stamp`` come from its ordering check, the
#: carrier feed's binding and plausibility gate add ``unbound``, ``source``, ``seq_jump``,
#: ``stamp_jump``, ``speed``, ``jump``, ``velocity`` and ``gap`` (:mod:`mission.bus.gate`), and
#: ``internal`` comes from a bug in a decoder, not from the codecs.
REASONS: tuple[str, ...] = (
    "size", "unsigned", "signature", "replay", "contest", "decode", "missing", "type", "shape", "nonfinite", "frame", "range", "orientation", "phase",
    "origin", "stale_seq", "stale_stamp", "unbound", "source", "seq_jump", "stamp_jump", "speed", "jump",
    "velocity", "gap", "internal",
)

SEQ_MAX = 2**63 - 1  # sequence numbers are int64, as in ROS 2 / DDS
POSITION_LIMIT_M = 1e7  # |local NED component| or |wgs84 altitude| [m]: beyond this a sample is corrupt
VELOCITY_LIMIT_M_S = 1e3  # |velocity component| [m/s]
ACCELERATION_LIMIT_M_S2 = 1e3  # |acceleration component| [m/s^2]



class WireError(MarsupialError):
    """A sample could not be decoded or failed validation. ``reason`` is one of :data:`REASONS`."""

    def __init__(self, reason: str, detail: str = "") -> None:
        self.reason, self.detail = reason, detail
        super().__init__(f"{reason}: {detail}" if detail else reason)


# --------------------------------------------------------------------------- values
#
# The messages are pydantic models. On the wire (JSON) numbers are strict: a string or a boolean is
# never a number, a fraction never an integer. In code, numpy scalars and arrays are taken as the
# Python values they hold. Pydantic's error types map to the drop reasons (:func:`wire_error`).


def _python_values(value: Any) -> Any:
    """A numpy scalar or array as the Python value(s) it holds (built in code, never on the wire)."""
    if isinstance(value, np.ndarray) and value.ndim != 0:
        if value.ndim != 1:
            raise PydanticCustomError("shape", "must be a vector, got shape {shape}", {"shape": value.shape})
        return value.tolist()
    return value.item() if isinstance(value, (np.generic, np.ndarray)) else value


def _frozen_array(values: list[float]) -> np.ndarray:
    out = np.array(values, dtype=float)
    out.flags.writeable = False
    return out


class _Checked:
    """Field annotation: ``Annotated[float, _Checked(core_schema.float_schema(...))]``. JSON input
    goes straight to ``schema`` (validated in Rust); Python input first through
    :func:`_python_values`."""

    def __init__(self, schema: core_schema.CoreSchema) -> None:
        self.schema = schema

    def __get_pydantic_core_schema__(self, source: Any, handler: Any) -> core_schema.CoreSchema:
        return core_schema.json_or_python_schema(
            json_schema=self.schema,
            python_schema=core_schema.no_info_before_validator_function(_python_values, self.schema))


def _vec3(limit: float) -> _Checked:
    """Exactly 3 finite numbers within +-``limit``, kept as a read-only float array (3,)."""
    items = core_schema.list_schema(core_schema.float_schema(strict=True, allow_inf_nan=False, ge=-limit, le=limit),
                                    min_length=3, max_length=3)
    return _Checked(core_schema.no_info_after_validator_function(
        _frozen_array, items, serialization=core_schema.plain_serializer_function_ser_schema(lambda a: a.tolist())))


Real = Annotated[float, _Checked(core_schema.float_schema(strict=True, allow_inf_nan=False))]
Seq = Annotated[int, _Checked(core_schema.int_schema(strict=True, ge=0, le=SEQ_MAX))]
Flag = Annotated[bool, _Checked(core_schema.bool_schema(strict=True))]
Duration = Annotated[float, _Checked(core_schema.float_schema(strict=True, allow_inf_nan=False, ge=0.0, le=1e6))]
Percent = Annotated[float, _Checked(core_schema.float_schema(strict=True, allow_inf_nan=False, ge=0.0, le=100.0))]
Sigma = Annotated[float, _Checked(core_schema.float_schema(strict=True, allow_inf_nan=False, ge=0.0, le=POSITION_LIMIT_M))]
#: An abort reason (``mission.phases.AbortReason`` values, and any later one): a short identifier.
AbortReasonName = Annotated[str, _Checked(core_schema.str_schema(strict=True, pattern=r"^[a-z_]{1,32}$"))]
PositionNed = Annotated[np.ndarray, _vec3(POSITION_LIMIT_M)]
VelocityNed = Annotated[np.ndarray, _vec3(VELOCITY_LIMIT_M_S)]
AccelerationNed = Annotated[np.ndarray, _vec3(ACCELERATION_LIMIT_M_S2)]

#: Pydantic error types and the drop reason each means; a type error not listed here is "type".
_REASON_OF_ERROR = {
    "json_invalid": "decode", "json_type": "decode", "model_type": "decode", "model_attributes_type": "decode",
    "missing": "missing", "finite_number": "nonfinite", "too_short": "shape", "too_long": "shape",
    "greater_than_equal": "range", "less_than_equal": "range", "greater_than": "range", "less_than": "range",
}


def _reason(error: Any) -> str:
    kind, value = error["type"], error.get("input")
    if kind in REASONS:  # our own PydanticCustomError types are reasons already
        return kind
    if kind in ("literal_error", "enum"):  # an unknown frame or phase; a non-string is a type error
        return str(error["loc"][0]) if isinstance(value, str) else "type"
    if kind == "float_type" and isinstance(value, int) and not isinstance(value, bool):
        return "nonfinite"  # an integer too large for a float
    return _REASON_OF_ERROR.get(kind, "type")


def wire_error(exc: ValidationError, check_order: tuple[str, ...] = ()) -> WireError:
    """The :class:`WireError` of a failed validation. Of several errors: a decode error, else a
    missing field, else the error of the field that comes first in ``check_order`` (field names
    or JSON names; the order the hand-written checks had), else the first."""
    errors = exc.errors(include_url=False)
    reasons = [_reason(e) for e in errors]

    def rank(i: int) -> tuple[int, int, int]:
        loc = errors[i]["loc"]
        field = loc[0] if loc else ""
        order = check_order.index(field) if field in check_order else len(check_order)
        return {"decode": 0, "missing": 1}.get(reasons[i], 2), order, i

    i = min(range(len(errors)), key=rank)
    where = ".".join(str(p) for p in errors[i]["loc"])
    return WireError(reasons[i], f"{where}: {errors[i]['msg']}" if where else errors[i]["msg"])


_VELOCITY = TypeAdapter(VelocityNed)


def velocity3(value: Any, name: str) -> np.ndarray:
    """``value`` as a read-only float array (3,) of finite numbers within +-:data:`VELOCITY_LIMIT_M_S`
    (a velocity [m/s] or an angular rate [rad/s]); raises :class:`WireError` naming ``name``."""
    try:
        return _VELOCITY.validate_python(value)
    except ValidationError as exc:
        err = wire_error(exc)
        raise WireError(err.reason, f"{name}: {err.detail}") from None


class _Message(BaseModel):
    """A bus message: frozen, validated on construction (:class:`WireError` when invalid). Field
    aliases are the JSON names; unknown JSON fields are ignored (forward compatibility).

    Subclasses take their fields positionally too (``CarrierState(stamp, seq, ...)``): their
    ``__init__`` only names the arguments and is marked ``__pydantic_base_init__``, the mark
    pydantic's own ``RootModel.__init__`` carries, so that decoding JSON (``from_json``) does not
    call it and stays in pydantic's compiled validator.
    """

    model_config = ConfigDict(frozen=True, extra="ignore", validate_by_name=True, validate_by_alias=True)

    #: The order in which fields are judged when a message has several faults (wire_error).
    _check_order: ClassVar[tuple[str, ...]] = ()

    def _validated(self, **fields: Any) -> None:
        try:
            super().__init__(**fields)
        except ValidationError as exc:
            raise wire_error(exc, self._check_order) from None

    @classmethod
    def from_json(cls, raw: bytes | bytearray | memoryview | str) -> Any:
        """The message of one JSON object (wire names only); raises :class:`WireError`."""
        try:
            return cls.model_validate_json(bytes(raw) if isinstance(raw, memoryview) else raw, by_alias=True,
                                           by_name=False)
        except ValidationError as exc:
            raise wire_error(exc, cls._check_order) from None

    def to_json(self) -> bytes:
        """The JSON bytes of this message (wire names)."""
        return self.model_dump_json(by_alias=True).encode()


class CarrierState(_Message):
    """The carrier's state as sent on the wire.

    stamp_s [s] sender's clock; seq (>= 0) per-sender sequence number; frame "local_ned" or
    "wgs84"; position: local_ned [m] (n, e, d), wgs84 (lat [deg], lon [deg], alt [m] AMSL up);
    velocity_ned_m_s [m/s] NED in both frames; yaw_rad [rad] heading from north towards east, or
    None; acceleration_ned_m_s2 [m/s^2] NED as measured by the carrier, or None (not sent);
    target_ned_m [m] local NED: the target a team's carrier heads for (JSON ``target``,
    :meth:`mission.carrier.team.TeamCarrier.heading_for_ned_m`; None: not announced, as a single
    pair's carrier and CDR Odometry). Arrays are read-only float (3,). Raises :class:`WireError` when
    invalid.
    """

    stamp_s: Real = Field(alias="stamp")
    seq: Seq
    frame: Frame
    position: PositionNed
    velocity_ned_m_s: VelocityNed = Field(alias="velocity")
    yaw_rad: Real | None = Field(None, alias="yaw")
    acceleration_ned_m_s2: AccelerationNed | None = Field(None, alias="acceleration")
    target_ned_m: PositionNed | None = Field(None, alias="target")

    _check_order = ("frame", "stamp", "stamp_s", "seq", "position", "velocity", "velocity_ned_m_s", "yaw", "yaw_rad",
                    "acceleration", "acceleration_ned_m_s2", "target", "target_ned_m")

    def __init__(self, stamp_s: float, seq: int, frame: str, position: Any, velocity_ned_m_s: Any,
                 yaw_rad: float | None = None, acceleration_ned_m_s2: Any = None, target_ned_m: Any = None) -> None:
        self._validated(stamp_s=stamp_s, seq=seq, frame=frame, position=position, velocity_ned_m_s=velocity_ned_m_s,
                        yaw_rad=yaw_rad, acceleration_ned_m_s2=acceleration_ned_m_s2, target_ned_m=target_ned_m)

    __init__.__pydantic_base_init__ = True  # type: ignore[attr-defined]  # see _Message

    def to_json(self) -> bytes:
        """The JSON bytes (wire names); ``target`` only when announced, so a single pair's states
        are the bytes they always were."""
        return self.model_dump_json(by_alias=True, exclude=None if self.target_ned_m is not None else {"target_ned_m"}).encode()

    @model_validator(mode="after")
    def _lat_lon(self) -> CarrierState:
        if self.frame == "wgs84":
            lat, lon, _ = self.position
            if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
                raise PydanticCustomError("range", "wgs84 lat/lon out of range: {lat}, {lon}", {"lat": lat, "lon": lon})
        return self


class PassengerStatus(_Message):
    """The passenger's mission phase and state.

    phase a :class:`~mission.phases.phase.Phase` (its name on the wire); stamp_s [s] sender's clock;
    seq (>= 0); position_ned_m [m] and
    velocity_ned_m_s [m/s] local NED; separated: the separation latch has fired; anchor_ned_m
    [m] the latched anchor (carrier position at separation) or None; leg: the index of the target
    served (``scenario.targets``; 0 with one target); reason: why the mission aborted (phase
    ABORT), or None; holding: the passenger holds on the dock point it had because its carrier
    feed is not consistent (a resync, a contested source): the carrier pauses until it rides
    again. A team's passenger also shares what its teammates' recovery queue reads
    (:mod:`mission.phases.queue`): recovery_s [s] how long its recovery has run at ``stamp``
    (JSON ``recovery``; None: not recovering) and battery_pct [%] its battery (JSON ``battery``;
    None: not known). With ``[relnav]`` (no shared frame) a passenger whose relative estimate
    has converged shares its estimate of the frames' bias, which the carrier's P3 guard may use
    (:mod:`mission.carrier.frames`): bias_ned_m [m] NED the carrier's GNSS frame minus the
    passenger's (JSON ``bias``) and bias_sigma_m [m] its largest standard deviation (JSON
    ``bias_sigma``), both or neither (None: not shared). Each goes on the wire only when given, so a
    single pair's statuses are the bytes they always were. Raises :class:`WireError` when invalid.
    """

    phase: Phase
    stamp_s: Real = Field(alias="stamp")
    seq: Seq
    position_ned_m: PositionNed = Field(alias="position")
    velocity_ned_m_s: VelocityNed = Field(alias="velocity")
    separated: Flag
    anchor_ned_m: PositionNed | None = Field(None, alias="anchor")
    leg: int = Field(0, ge=0, le=1000, strict=True)
    reason: AbortReasonName | None = None
    holding: Flag = False
    recovery_s: Duration | None = Field(None, alias="recovery")
    battery_pct: Percent | None = Field(None, alias="battery")
    bias_ned_m: PositionNed | None = Field(None, alias="bias")
    bias_sigma_m: Sigma | None = Field(None, alias="bias_sigma")

    _check_order = ("phase", "separated", "holding", "stamp", "stamp_s", "seq", "position", "position_ned_m",
                    "velocity", "velocity_ned_m_s", "anchor", "anchor_ned_m", "leg", "reason", "recovery", "recovery_s",
                    "battery", "battery_pct", "bias", "bias_ned_m", "bias_sigma", "bias_sigma_m")
    _OPTIONAL: ClassVar[tuple[str, ...]] = ("recovery_s", "battery_pct", "bias_ned_m", "bias_sigma_m")

    def __init__(self, phase: Phase | str, stamp_s: float, seq: int, position_ned_m: Any, velocity_ned_m_s: Any,
                 separated: bool = False, anchor_ned_m: Any = None, leg: int = 0, reason: str | None = None,
                 holding: bool = False, recovery_s: float | None = None, battery_pct: float | None = None,
                 bias_ned_m: Any = None, bias_sigma_m: float | None = None) -> None:
        self._validated(phase=phase, stamp_s=stamp_s, seq=seq, position_ned_m=position_ned_m,
                        velocity_ned_m_s=velocity_ned_m_s, separated=separated, anchor_ned_m=anchor_ned_m, leg=leg,
                        reason=reason, holding=holding, recovery_s=recovery_s, battery_pct=battery_pct,
                        bias_ned_m=bias_ned_m, bias_sigma_m=bias_sigma_m)

    __init__.__pydantic_base_init__ = True  # type: ignore[attr-defined]  # see _Message

    @model_validator(mode="after")
    def _bias_pair(self) -> PassengerStatus:
        if (self.bias_ned_m is None) != (self.bias_sigma_m is None):
            raise PydanticCustomError("missing", "bias and bias_sigma go together")
        return self

    def to_json(self) -> bytes:
        """The JSON bytes (wire names); ``recovery`` and ``battery`` only when given (a team's),
        ``bias`` and ``bias_sigma`` only when given (relnav's, converged)."""
        skip = {k for k in self._OPTIONAL if getattr(self, k) is None}
        return self.model_dump_json(by_alias=True, exclude=skip or None).encode()


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
    (:func:`mission.core.geodesy.project`); down = origin altitude minus altitude."""
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
    lat, lon, alt = (float(v) for v in state.position)
    ned = geodetic_to_ned(lat, lon, alt, origin)
    return CarrierState(state.stamp_s, state.seq, "local_ned", ned, state.velocity_ned_m_s, state.yaw_rad,
                        state.acceleration_ned_m_s2, state.target_ned_m)


# --------------------------------------------------------------------------- JSON


def encode_carrier_json(state: CarrierState) -> bytes:
    """The JSON bytes of ``state`` (schema in the module docstring)."""
    return state.to_json()


def decode_carrier_json(raw: bytes | bytearray | memoryview | str) -> CarrierState:
    """A validated :class:`CarrierState` from JSON bytes; raises :class:`WireError`.

    JSON's non-standard ``NaN``/``Infinity`` literals are parsed, then rejected as "nonfinite".
    """
    return CarrierState.from_json(raw)


def encode_passenger_json(status: PassengerStatus) -> bytes:
    """The JSON bytes of ``status`` (schema in the module docstring)."""
    return status.to_json()


def decode_passenger_json(raw: bytes | bytearray | memoryview | str) -> PassengerStatus:
    """A validated :class:`PassengerStatus` from JSON bytes; raises :class:`WireError`."""
    return PassengerStatus.from_json(raw)
