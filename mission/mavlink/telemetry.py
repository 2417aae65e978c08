"""What the vehicle told us, as a pure reducer of received messages.

:func:`reduce` maps ``(telemetry, message, t_rx) -> telemetry`` for the messages a mission
reads (HEARTBEAT, LOCAL_POSITION_NED, EXTENDED_SYS_STATE, SYS_STATUS, BATTERY_STATUS,
GPS_GLOBAL_ORIGIN, HOME_POSITION, ATTITUDE); other
messages leave it unchanged. :func:`snapshot` turns it into the immutable :class:`VehicleState`
a caller sees at one clock time. :class:`StatusTextAssembler` joins chunked STATUSTEXTs.
:func:`downward_range` reads a DISTANCE_SENSOR (the rangefinder feed, :mod:`mission.cli.rangefinder`). Times
are link-clock seconds [s]; positions and velocities PX4's local NED frame.

No single sample decides that the vehicle is disarmed or landed (the verdicts a mission aborts
on): on an unsigned link anyone who can put a packet on the vehicle's address can forge one.
Once the vehicle was believed armed (or not landed), a disarmed HEARTBEAT is believed when
EXTENDED_SYS_STATE says ON_GROUND too, or when HEARTBEATs have said disarmed for
:data:`DISARMED_AGREE_S` with no armed one between; an ON_GROUND is believed when the
HEARTBEAT says disarmed too, or when EXTENDED_SYS_STATEs have said ON_GROUND for
:data:`LANDED_AGREE_S` with nothing else between. Armed and in the air are believed at once.
On a signed link (``Telemetry.signed``) every sample is the vehicle's own and decides alone.
"""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from mission.core.records import replace
from mission.mavlink import px4
from mission.mavlink.env import mavlink
from mission.passenger.inputs import VehicleReport
from mission.phases.measurements import DownwardRange

STATUSTEXT_CHUNK_LEN = 50
LANDED_AGREE_S = 0.08
"""Unsigned link: EXTENDED_SYS_STATE must say ON_GROUND this long [s] (at least two samples;
the mission asks for it at 10 Hz) before it is believed alone."""
DISARMED_AGREE_S = 0.5
"""Unsigned link: HEARTBEAT must say disarmed this long [s] (at least two; PX4 sends it at 1 Hz)
before it is believed alone."""


@dataclass(frozen=True, eq=False)
class VehicleState:
    """Immutable snapshot of the vehicle's telemetry, as the link last heard it.

    Times are link-clock seconds [s]. Positions and velocities are PX4's local NED frame
    (x north, y east, z down) relative to the EKF origin; arrays are read-only.
    """

    t_s: float
    """Clock time the snapshot was taken [s]."""
    system_id: int | None
    """Identified vehicle system id (None before identification)."""
    component_id: int | None
    """Identified autopilot component id (None before identification)."""
    position_ned_m: np.ndarray | None
    """Position [m] NED, shape (3,), from LOCAL_POSITION_NED; None before the first one."""
    velocity_ned_m_s: np.ndarray | None
    """Velocity [m/s] NED, shape (3,), from LOCAL_POSITION_NED; None before the first one."""
    position_rx_s: float | None
    """Clock time the last LOCAL_POSITION_NED was received [s]."""
    heartbeat_rx_s: float | None
    """Clock time the last vehicle HEARTBEAT was received [s]."""
    armed: bool
    """HEARTBEAT base_mode has MAV_MODE_FLAG_SAFETY_ARMED."""
    mode: str
    """PX4 mode name (:func:`mission.mavlink.px4.mode_name`), e.g. ``"OFFBOARD"``; ``""`` before a HEARTBEAT."""
    custom_mode: int
    """Raw HEARTBEAT custom_mode."""
    base_mode: int
    """Raw HEARTBEAT base_mode."""
    system_status: int
    """HEARTBEAT system_status (MAV_STATE: 3 STANDBY, 4 ACTIVE, 5 CRITICAL...)."""
    landed_state: int | None
    """EXTENDED_SYS_STATE landed_state (1 ON_GROUND, 2 IN_AIR, 3 TAKEOFF, 4 LANDING) or None."""
    position_valid: bool
    """A fresh, finite LOCAL_POSITION_NED (age <= the link's position_timeout_s) and, when
    SYS_STATUS reports the AHRS/estimator as present and enabled, that it is healthy."""
    origin: tuple[float, float, float] | None
    """EKF origin (lat [deg], lon [deg], alt [m] AMSL) from GPS_GLOBAL_ORIGIN, or None."""
    last_statustext: str
    """Text of the latest (reassembled) STATUSTEXT from the vehicle, ``""`` if none."""
    yaw_rad: float | None = None
    """Heading [rad] from north towards east, from ATTITUDE; None before the first (or non-finite)."""
    position_t_s: float | None = None
    """Clock time the vehicle took that sample [s]: its ``time_boot_ms`` mapped onto the link
    clock (:func:`vehicle_time_to_link`); earlier than ``position_rx_s`` by the transport delay and
    by however long the sample waited to be read (a stalled process reads a burst of old
    samples at once)."""
    battery_pct: float | None = None
    """Battery remaining [%] the vehicle reports, or None (not reported): the lowest of SYS_STATUS's
    ``battery_remaining`` and every battery's BATTERY_STATUS (PX4 sends -1 when it does not know:
    None); PX4 rounds its estimate up to a whole per cent."""
    home_ned_m: np.ndarray | None = None
    """PX4's home [m] NED, shape (3,), from HOME_POSITION's local x, y, z; None before the first."""
    home_rx_s: float | None = None
    """Clock time the last HOME_POSITION was received [s]."""
    believed_armed: bool = False
    """Armed, unless a disarm was confirmed (module docstring): what a mission's disarmed verdict reads."""
    believed_on_ground: bool = False
    """Landed (ON_GROUND) as confirmed (module docstring): what a mission's landed verdict reads."""
    vehicle_clock_offset_s: float | None = None
    """The link clock less the vehicle's boot clock [s]: a ``time_boot_ms`` / 1000 plus it is that
    sample's time on the link clock, as learned from LOCAL_POSITION_NED (:func:`vehicle_time_to_link`,
    the same that gives ``position_t_s``); None before the first."""

    @property
    def heartbeat_age_s(self) -> float:
        """Seconds since the last vehicle HEARTBEAT at snapshot time (inf if none) [s]."""
        return math.inf if self.heartbeat_rx_s is None else self.t_s - self.heartbeat_rx_s

    @property
    def position_age_s(self) -> float:
        """Seconds since the last LOCAL_POSITION_NED at snapshot time (inf if none) [s]."""
        return math.inf if self.position_rx_s is None else self.t_s - self.position_rx_s


def vehicle_report(state: VehicleState) -> VehicleReport | None:
    """What the passenger's step reads of ``state`` (None: no vehicle HEARTBEAT yet): its last
    LOCAL_POSITION_NED with the vehicle's sample time and our receive time, the believed armed and
    landed verdicts, and system_status CRITICAL as a failsafe."""
    if state.heartbeat_rx_s is None:
        return None
    return VehicleReport(
        t_s=state.t_s, position_ned_m=state.position_ned_m, velocity_ned_m_s=state.velocity_ned_m_s,
        sample_t_s=state.position_t_s, rx_s=state.position_rx_s, armed=state.believed_armed, mode=state.mode,
        heartbeat_age_s=state.heartbeat_age_s, valid=state.position_valid,
        in_failsafe=state.system_status == px4.MAV_STATE_CRITICAL, battery_pct=state.battery_pct,
        on_ground=state.believed_on_ground)


@dataclass(frozen=True, eq=False)
class Telemetry:
    """Everything the reducer keeps (see :class:`VehicleState` for the fields' meaning);
    ``position_finite``: position and velocity all finite; ``ahrs_healthy``: None when SYS_STATUS
    does not report the estimator as present and enabled."""

    position_ned_m: np.ndarray | None = None
    velocity_ned_m_s: np.ndarray | None = None
    position_finite: bool = False
    position_rx_s: float | None = None
    position_t_s: float | None = None
    vehicle_clock: tuple[float, float, float] | None = None  # (offset, last vehicle time, last link time) [s]
    heartbeat_rx_s: float | None = None
    base_mode: int = 0
    custom_mode: int = 0
    mode: str = ""
    system_status: int = 0
    landed_state: int | None = None
    ahrs_healthy: bool | None = None
    origin: tuple[float, float, float] | None = None
    yaw_rad: float | None = None
    last_statustext: str = ""
    battery_sys_pct: float | None = None  # SYS_STATUS battery_remaining [%] (None: -1, unknown)
    battery_ids_pct: tuple[tuple[int, float | None], ...] = ()  # BATTERY_STATUS (id, remaining [%]) per battery
    home_ned_m: np.ndarray | None = None
    home_rx_s: float | None = None
    signed: bool = False  # every sample was signed with the link's key: each decides alone
    believed_armed: bool = False
    disarmed_since_s: float | None = None  # first of the disarmed HEARTBEATs since the last armed one [s]
    believed_on_ground: bool = False
    on_ground_since_s: float | None = None  # first of the ON_GROUND samples since the last other one [s]
    on_ground_rx_s: float | None = None  # the last of them [s]

    @property
    def battery_pct(self) -> float | None:
        """The lowest battery remaining [%] any message reported (None: none known)."""
        known = [p for p in (self.battery_sys_pct, *(pct for _, pct in self.battery_ids_pct)) if p is not None]
        return min(known) if known else None


def _readonly_vector(x: float, y: float, z: float) -> np.ndarray:
    v = np.array([x, y, z], dtype=float)
    v.setflags(write=False)
    return v


def _believed(tm: Telemetry) -> Telemetry:
    """The armed and landed beliefs after a HEARTBEAT or EXTENDED_SYS_STATE (module docstring)."""
    armed = bool(tm.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
    on_ground = tm.landed_state == px4.LANDED_ON_GROUND
    believed_armed, believed_on_ground = tm.believed_armed, tm.believed_on_ground
    if armed:
        believed_armed = True
    elif believed_armed and tm.heartbeat_rx_s is not None and tm.disarmed_since_s is not None:
        believed_armed = not (tm.signed or on_ground or tm.heartbeat_rx_s - tm.disarmed_since_s >= DISARMED_AGREE_S)
    if not on_ground:
        believed_on_ground = False
    elif not believed_on_ground and tm.on_ground_since_s is not None and tm.on_ground_rx_s is not None:
        disarmed = not armed and tm.heartbeat_rx_s is not None
        believed_on_ground = tm.signed or disarmed or tm.on_ground_rx_s - tm.on_ground_since_s >= LANDED_AGREE_S
    return replace(tm, believed_armed=believed_armed, believed_on_ground=believed_on_ground)


def _heartbeat(tm: Telemetry, msg: Any, t_rx: float) -> Telemetry:
    custom_mode = int(msg.custom_mode)
    armed = bool(int(msg.base_mode) & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
    since = None if armed else (t_rx if tm.disarmed_since_s is None else tm.disarmed_since_s)
    return _believed(replace(tm, heartbeat_rx_s=t_rx, base_mode=int(msg.base_mode), custom_mode=custom_mode,
                             mode=px4.mode_name(custom_mode), system_status=int(msg.system_status),
                             disarmed_since_s=since))


VEHICLE_CLOCK_DRIFT = 0.1  # how fast the vehicle-to-link offset may grow [s/s]


def vehicle_time_to_link(state: tuple[float, float, float] | None, t_vehicle_s: float, t_rx_s: float,
                         drift: float = VEHICLE_CLOCK_DRIFT) -> tuple[float, tuple[float, float, float]]:
    """Map the vehicle's ``time_boot_ms`` [s] onto the link clock [s]: ``(t_link, new state)``.

    The offset ``t_link - t_vehicle`` is the smallest one seen (the least-delayed sample), allowed
    to grow by ``drift`` seconds per second so a vehicle clock running slower than ours (PX4 SITL
    at 0.9x) is followed; a vehicle reboot (time going backwards) starts afresh. ``state`` is
    ``(offset, last vehicle time, last link time)`` or None before the first sample.
    """
    offset = t_rx_s - t_vehicle_s
    if state is not None and t_vehicle_s >= state[1]:
        offset = min(state[0] + drift * max(t_rx_s - state[2], 0.0), offset)
    return t_vehicle_s + offset, (offset, t_vehicle_s, t_rx_s)


def vehicle_clock_offset_s(state: tuple[float, float, float] | None) -> float | None:
    """The link clock less the vehicle's boot clock [s] that :func:`vehicle_time_to_link` last
    settled on (``state`` as it keeps it; None before the first sample): a vehicle time plus it
    is that time on the link clock."""
    return None if state is None else state[0]


DOWNWARD = mavlink.MAV_SENSOR_ROTATION_PITCH_270  # 25: DISTANCE_SENSOR's orientation for a downward sensor
COVARIANCE_UNKNOWN = 255  # DISTANCE_SENSOR covariance [cm^2]: UINT8_MAX if unknown
SIGNAL_INVALID = 1  # DISTANCE_SENSOR signal_quality [%]: 0 unknown, 1 invalid, 100 perfect
#: Why :func:`downward_range` drops a DISTANCE_SENSOR (the rangefinder feed's counters).
RANGE_DROPS = ("other_orientation", "invalid_signal", "out_of_range", "malformed", "unclocked")


def downward_range(msg: Any, clock_offset_s: float | None, default_sigma_m: float) -> DownwardRange | str:
    """A DISTANCE_SENSOR as a :class:`~mission.phases.measurements.DownwardRange`, or why not
    (a name of :data:`RANGE_DROPS`). Pure: ``msg`` needs only the message's fields.

    The message (MAVLink common.xml, DISTANCE_SENSOR, id 132): ``time_boot_ms`` [ms] the vehicle's
    boot clock at the sample (PX4 streams its sample's timestamp: PX4-Autopilot
    src/modules/mavlink/streams/DISTANCE_SENSOR.hpp), ``min_distance``, ``max_distance``,
    ``current_distance`` [cm], ``orientation`` (MAV_SENSOR_ROTATION_PITCH_270 = 25: downward),
    ``covariance`` [cm^2] (UINT8_MAX if unknown; PX4 sends its variance in cm^2, 0 when its driver
    set none), ``signal_quality`` [%] (0 unknown, 1 invalid, 100 perfect; a MAVLink 2 extension).

    Dropped: ``malformed`` (a field that is no integer of its range, ``max_distance`` 0 or below
    ``min_distance``), ``other_orientation`` (any orientation but downward), ``invalid_signal``
    (signal_quality 1), ``out_of_range`` (``current_distance`` outside ``[min_distance,
    max_distance]``), ``unclocked`` (``clock_offset_s`` None: the link knows no vehicle time yet).
    Kept: ``range_m`` = current_distance / 100 [m], captured at ``time_boot_ms / 1000 +
    clock_offset_s`` [s, link clock] (:func:`vehicle_clock_offset_s`), ``sigma_m`` =
    sqrt(covariance) / 100 [m], or ``default_sigma_m`` [m] when the covariance is 0 or 255.
    """
    try:
        boot_ms, low, high, current, orientation, covariance = (
            _uint(msg.time_boot_ms, 32), _uint(msg.min_distance, 16), _uint(msg.max_distance, 16),
            _uint(msg.current_distance, 16), _uint(msg.orientation, 8), _uint(msg.covariance, 8))
        quality = _uint(getattr(msg, "signal_quality", 0), 8)
    except (AttributeError, TypeError, ValueError):
        return "malformed"
    if high == 0 or high < low:
        return "malformed"
    if orientation != DOWNWARD:
        return "other_orientation"
    if quality == SIGNAL_INVALID:
        return "invalid_signal"
    if not low <= current <= high:
        return "out_of_range"
    if clock_offset_s is None or not math.isfinite(clock_offset_s):
        return "unclocked"
    sigma_m = default_sigma_m if covariance in (0, COVARIANCE_UNKNOWN) else math.sqrt(covariance) / 100.0
    return DownwardRange(capture_t_s=boot_ms * 1e-3 + clock_offset_s, range_m=current / 100.0, sigma_m=sigma_m)


def _uint(value: Any, bits: int) -> int:
    """``value`` as an unsigned integer of ``bits`` bits; ValueError or TypeError if it is not one."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"not an integer: {value!r}")
    if not 0 <= int(value) < 1 << bits:
        raise ValueError(f"outside uint{bits}: {value!r}")
    return int(value)


def _local_position(tm: Telemetry, msg: Any, t_rx: float) -> Telemetry:
    position, velocity = (msg.x, msg.y, msg.z), (msg.vx, msg.vy, msg.vz)
    finite = all(math.isfinite(c) for c in position + velocity)
    t_sample, clock_state = vehicle_time_to_link(tm.vehicle_clock, msg.time_boot_ms * 1e-3, t_rx)
    return replace(tm, position_ned_m=_readonly_vector(*position), velocity_ned_m_s=_readonly_vector(*velocity),
                   position_finite=finite, position_rx_s=t_rx, position_t_s=t_sample, vehicle_clock=clock_state)


def _extended_sys_state(tm: Telemetry, msg: Any, t_rx: float) -> Telemetry:
    landed = int(msg.landed_state)
    on_ground = landed == px4.LANDED_ON_GROUND
    since = (t_rx if tm.on_ground_since_s is None else tm.on_ground_since_s) if on_ground else None
    return _believed(replace(tm, landed_state=landed, on_ground_since_s=since, on_ground_rx_s=t_rx if on_ground else None))


def _remaining_pct(value: int) -> float | None:
    """``battery_remaining`` [%] of SYS_STATUS / BATTERY_STATUS: -1 (or anything outside 0..100) is unknown."""
    return float(value) if 0 <= value <= 100 else None


def _sys_status(tm: Telemetry, msg: Any, t_rx: float) -> Telemetry:
    bit = mavlink.MAV_SYS_STATUS_AHRS
    reported = msg.onboard_control_sensors_present & bit and msg.onboard_control_sensors_enabled & bit
    return replace(tm, ahrs_healthy=bool(msg.onboard_control_sensors_health & bit) if reported else None,
                   battery_sys_pct=_remaining_pct(int(msg.battery_remaining)))


def _battery_status(tm: Telemetry, msg: Any, t_rx: float) -> Telemetry:
    others = tuple(pair for pair in tm.battery_ids_pct if pair[0] != int(msg.id))
    return replace(tm, battery_ids_pct=(*others, (int(msg.id), _remaining_pct(int(msg.battery_remaining)))))


def _home_position(tm: Telemetry, msg: Any, t_rx: float) -> Telemetry:
    home = (float(msg.x), float(msg.y), float(msg.z))
    if not all(math.isfinite(c) for c in home):
        return tm
    return replace(tm, home_ned_m=_readonly_vector(*home), home_rx_s=t_rx)


def _origin(tm: Telemetry, msg: Any, t_rx: float) -> Telemetry:
    return replace(tm, origin=(msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3))


def _attitude(tm: Telemetry, msg: Any, t_rx: float) -> Telemetry:
    yaw = float(msg.yaw)
    return replace(tm, yaw_rad=yaw if math.isfinite(yaw) else None)


_REDUCERS = {
    "HEARTBEAT": _heartbeat,
    "LOCAL_POSITION_NED": _local_position,
    "EXTENDED_SYS_STATE": _extended_sys_state,
    "SYS_STATUS": _sys_status,
    "BATTERY_STATUS": _battery_status,
    "GPS_GLOBAL_ORIGIN": _origin,
    "HOME_POSITION": _home_position,
    "ATTITUDE": _attitude,
}
KINDS = frozenset(_REDUCERS)
"""Message types :func:`reduce` reads."""


def reduce(tm: Telemetry, msg: Any, t_rx: float) -> Telemetry:
    """The telemetry after ``msg`` (received at ``t_rx`` [s]); unchanged for other messages."""
    reducer = _REDUCERS.get(msg.get_type())
    return tm if reducer is None else reducer(tm, msg, t_rx)


def snapshot(tm: Telemetry, now_s: float, vehicle: tuple[int, int] | None, position_timeout_s: float) -> VehicleState:
    """What a caller sees at clock time ``now_s``: position valid while fresh (age <=
    ``position_timeout_s``), finite and not reported unhealthy by SYS_STATUS."""
    fresh = tm.position_rx_s is not None and now_s - tm.position_rx_s <= position_timeout_s and tm.position_finite
    return VehicleState(
        t_s=now_s,
        system_id=None if vehicle is None else vehicle[0],
        component_id=None if vehicle is None else vehicle[1],
        position_ned_m=tm.position_ned_m,
        velocity_ned_m_s=tm.velocity_ned_m_s,
        position_rx_s=tm.position_rx_s,
        position_t_s=tm.position_t_s,
        heartbeat_rx_s=tm.heartbeat_rx_s,
        armed=bool(tm.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED),
        mode=tm.mode,
        custom_mode=tm.custom_mode,
        base_mode=tm.base_mode,
        system_status=tm.system_status,
        landed_state=tm.landed_state,
        position_valid=bool(fresh) and tm.ahrs_healthy is not False,
        origin=tm.origin,
        yaw_rad=tm.yaw_rad,
        last_statustext=tm.last_statustext,
        battery_pct=tm.battery_pct,
        home_ned_m=tm.home_ned_m,
        home_rx_s=tm.home_rx_s,
        believed_armed=tm.believed_armed,
        believed_on_ground=tm.believed_on_ground,
        vehicle_clock_offset_s=vehicle_clock_offset_s(tm.vehicle_clock),
    )


class StatusTextAssembler:
    """Reassembles chunked STATUSTEXT (MAVLink 2 ``id``/``chunk_seq``); a chunk shorter than
    50 characters ends a text. Keeps at most ``max_pending`` texts pending."""

    def __init__(self, max_pending: int = 4) -> None:
        self._pending: collections.OrderedDict[int, dict[int, str]] = collections.OrderedDict()
        self._max_pending = max_pending

    def feed(self, text: str, text_id: int, chunk_seq: int) -> str | None:
        """Add one chunk; return the whole text when complete, else None."""
        if text_id == 0:
            return text
        parts = self._pending.setdefault(text_id, {})
        parts[chunk_seq] = text
        if len(text) < STATUSTEXT_CHUNK_LEN:
            del self._pending[text_id]
            return "".join(parts[k] for k in sorted(parts))
        while len(self._pending) > self._max_pending:
            self._pending.popitem(last=False)
        return None


def with_statustext(tm: Telemetry, text: str) -> Telemetry:
    """The telemetry with ``text`` as the latest whole STATUSTEXT."""
    return replace(tm, last_statustext=text)
