"""Telemetry of the mock vehicle: the onboard-profile streams and their MAVLink messages.

Message builders are plain functions of a :class:`TelemetryState` (one consistent picture of the
vehicle taken under its lock). Geodetic output is PX4's own projection of local NED around the
EKF origin (``home`` option; :mod:`mission.core.geodesy`).

Stream rates are PX4's onboard profile in simulated Hz (measured on a PX4 SITL, see
../shared/REFERENCE.md); every rate scales with the speed factor. SET_MESSAGE_INTERVAL changes
the simulated rate, up to the most PX4 delivers (the rate its source topic is published at,
measured on SITL: LOCAL_POSITION_NED and ODOMETRY 125 Hz, ATTITUDE 220 Hz). So that a sped-up
run stays cheap, each stream's wall-clock rate is capped: LOCAL_POSITION_NED and HEARTBEAT at
:data:`CAP_PRIMARY_WALL_HZ`, ATTITUDE at :data:`CAP_ATTITUDE_WALL_HZ`, every other
stream at :data:`CAP_OTHER_WALL_HZ`. At speed 1 no cap bites (PX4's rates exactly); at speed 20
LOCAL_POSITION_NED arrives at 300 Hz wall (15 Hz simulated), ATTITUDE at 100 Hz wall (5 Hz
simulated), SYS_STATUS at 50 Hz wall (2.5 Hz simulated).
DISTANCE_SENSOR is no stream of this table: a vehicle with a rangefinder
(``VehicleOptions.rangefinder``) sends each reading as it is due (:class:`RangeStream`).
*Not streamed: PX4's own TIMESYNC requests and SYSTEM_TIME (the lockstep clock uses them), and
the messages our clients never read (SERVO_OUTPUT_RAW, GPS_RAW_INT, ...).
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import Any

from mission.core import geodesy

from mission.mavlink import px4, setpoints
from mission.mavlink.env import mavlink
from mission.mavlink.telemetry import COVARIANCE_UNKNOWN, DOWNWARD
from sim.vehicle.modes import TrajectorySetpoint
from sim.vehicle.estimator import EstimateError
from mission.config.relnav import RangefinderSection
from sim.vehicle.physics.deck import Deck
from sim.vehicle.physics.multicopter import GRAVITY_M_S2, KinState, attitude_rad, quaternion
from sim.vehicle.physics.rangefinder import Rangefinder, range_below_m

CAP_PRIMARY_WALL_HZ = 300.0
CAP_OTHER_WALL_HZ = 50.0
CAP_ATTITUDE_WALL_HZ = 100.0

SOURCE_MAX_HZ = 200.0  # a stream can go no faster than the physics step (PHYSICS_DT_S 5 ms)

# name, default rate [Hz simulated], wall-clock cap [Hz], most PX4 delivers [Hz simulated]
STREAM_TABLE: tuple[tuple[str, float, float, float], ...] = (
    ("HEARTBEAT", 1.0, CAP_PRIMARY_WALL_HZ, 1.0),  # PX4 refuses to change it
    ("LOCAL_POSITION_NED", 30.0, CAP_PRIMARY_WALL_HZ, 125.0),
    ("ODOMETRY", 30.0, CAP_OTHER_WALL_HZ, 125.0),
    ("ATTITUDE", 100.0, CAP_ATTITUDE_WALL_HZ, 220.0),
    ("ATTITUDE_QUATERNION", 50.0, CAP_OTHER_WALL_HZ, 220.0),
    ("GLOBAL_POSITION_INT", 50.0, CAP_OTHER_WALL_HZ, 125.0),
    ("HIGHRES_IMU", 50.0, CAP_OTHER_WALL_HZ, SOURCE_MAX_HZ),
    ("POSITION_TARGET_LOCAL_NED", 10.0, CAP_OTHER_WALL_HZ, SOURCE_MAX_HZ),
    ("ATTITUDE_TARGET", 10.0, CAP_OTHER_WALL_HZ, SOURCE_MAX_HZ),
    ("ALTITUDE", 10.0, CAP_OTHER_WALL_HZ, SOURCE_MAX_HZ),
    ("VFR_HUD", 10.0, CAP_OTHER_WALL_HZ, SOURCE_MAX_HZ),
    ("SYS_STATUS", 5.0, CAP_OTHER_WALL_HZ, SOURCE_MAX_HZ),
    ("EXTENDED_SYS_STATE", 5.0, CAP_OTHER_WALL_HZ, SOURCE_MAX_HZ),
    ("ESTIMATOR_STATUS", 1.0, CAP_OTHER_WALL_HZ, SOURCE_MAX_HZ),
    ("GPS_GLOBAL_ORIGIN", 1.0, CAP_OTHER_WALL_HZ, SOURCE_MAX_HZ),
    ("HOME_POSITION", 0.5, CAP_OTHER_WALL_HZ, SOURCE_MAX_HZ),
    ("BATTERY_STATUS", 0.5, CAP_OTHER_WALL_HZ, SOURCE_MAX_HZ),
)

SENSORS_PRESENT = (px4.SENSOR_3D_GYRO | px4.SENSOR_3D_ACCEL | px4.SENSOR_3D_MAG | px4.SENSOR_ABSOLUTE_PRESSURE
                   | px4.SENSOR_GPS | px4.SENSOR_ANGULAR_RATE_CONTROL | px4.SENSOR_ATTITUDE_STABILIZATION
                   | px4.SENSOR_YAW_POSITION | px4.SENSOR_Z_ALTITUDE_CONTROL | px4.SENSOR_XY_POSITION_CONTROL
                   | px4.SENSOR_MOTOR_OUTPUTS | px4.SENSOR_AHRS | px4.SENSOR_PREARM_CHECK | px4.SYS_STATUS_EXTENSION_USED)
CAPABILITIES = (px4.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | px4.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
                | px4.MAV_PROTOCOL_CAPABILITY_MISSION_INT | px4.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | px4.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                | px4.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT | px4.MAV_PROTOCOL_CAPABILITY_MAVLINK2)
NO_CURRENT_CA = -100  # [cA]: PX4's battery simulator has no current sensor (-1 A), as SITL sends it
ESTIMATOR_TYPE_AUTOPILOT = 8  # MAV_ESTIMATOR_TYPE_AUTOPILOT, as PX4 fills ODOMETRY
ESTIMATOR_FLAGS_HEALTHY = 895  # ESTIMATOR_STATUS.flags seen on a healthy PX4 SITL
ESTIMATOR_FLAGS_ATTITUDE_ONLY = 0x3  # attitude and horizontal velocity only
EARTH_FIELD_NED_GAUSS = (0.21, 0.01, 0.43)  # roughly Zurich's, SIH's default location
FLIGHT_SW_VERSION = (1 << 24) | (16 << 16) | (0 << 8) | 255  # 1.16.0 release, as PX4 encodes it


@dataclass
class Stream:
    """One periodic message: its period [s, simulated] after the wall cap, and next due time."""

    name: str
    msg_id: int
    default_rate_hz: float
    wall_cap_hz: float
    max_rate_hz: float = SOURCE_MAX_HZ
    rate_hz: float = 0.0  # as configured (SET_MESSAGE_INTERVAL), 0: disabled
    period_s: float = 0.0  # 0: disabled
    next_due_s: float = 0.0

    def set_rate(self, rate_hz: float, speed: float) -> None:
        """Set the simulated rate [Hz]; <= 0 disables. It is delivered up to ``max_rate_hz``,
        and the wall cap bounds rate * speed."""
        self.rate_hz = max(rate_hz, 0.0)
        self.period_s = 0.0 if rate_hz <= 0 else max(1.0 / min(rate_hz, self.max_rate_hz), speed / self.wall_cap_hz)

    def interval_us(self) -> int:
        """The configured interval [us] as MESSAGE_INTERVAL reports it (PX4: 0 when not streamed)."""
        return round(1e6 / self.rate_hz) if self.rate_hz > 0 else 0


def make_streams(speed: float) -> dict[str, Stream]:
    """The onboard-profile streams at their default rates for clock ``speed``."""
    streams = {}
    for name, rate_hz, cap_hz, max_hz in STREAM_TABLE:
        stream = Stream(name, getattr(mavlink, f"MAVLINK_MSG_ID_{name}"), rate_hz, cap_hz, max_hz)
        stream.set_rate(rate_hz, speed)
        streams[name] = stream
    return streams


@dataclass(frozen=True)
class Geo:
    """PX4's projection (:mod:`mission.core.geodesy`) around the EKF origin: latitude, longitude [deg],
    altitude [m AMSL]."""

    lat0_deg: float
    lon0_deg: float
    alt0_m: float

    def to_geodetic(self, n_m: float, e_m: float, d_m: float) -> tuple[float, float, float]:
        """Local NED [m] -> (lat [deg], lon [deg], alt [m AMSL])."""
        lat, lon = geodesy.reproject(n_m, e_m, self.lat0_deg, self.lon0_deg)
        return lat, lon, self.alt0_m - d_m

    def to_local(self, lat_deg: float, lon_deg: float, alt_m: float) -> tuple[float, float, float]:
        """(lat [deg], lon [deg], alt [m AMSL]) -> local NED [m] (NaN in, NaN out)."""
        if not all(math.isfinite(c) for c in (lat_deg, lon_deg, alt_m)):
            return math.nan, math.nan, math.nan
        n, e = geodesy.project(lat_deg, lon_deg, self.lat0_deg, self.lon0_deg)
        return n, e, self.alt0_m - alt_m


@dataclass(frozen=True)
class TelemetryState:
    """Everything the streams report, taken at one instant (``t_s`` simulated seconds)."""

    t_s: float
    kin: KinState
    mode: str
    armed: bool
    system_status: int
    landed_state: int
    armable: bool
    position_valid: bool
    setpoint: TrajectorySetpoint | None
    home_ned_m: tuple[float, float, float]
    mav_type: int = px4.MAV_TYPE_QUADROTOR
    battery: tuple[int, int] | None = None  # (remaining [%], voltage [mV]) of the simulated battery, None: none


def _ms(t_s: float) -> int:
    return int(t_s * 1000.0) & 0xFFFFFFFF


def _us(t_s: float) -> int:
    return int(t_s * 1e6)


def heartbeat(s: TelemetryState) -> Any:
    return mavlink.MAVLink_heartbeat_message(
        s.mav_type, px4.MAV_AUTOPILOT_PX4, px4.base_mode_of(s.mode, s.armed),
        px4.custom_mode_of(s.mode), s.system_status, 3)


def sys_status(s: TelemetryState) -> Any:
    health = SENSORS_PRESENT
    if not s.armable:
        health &= ~px4.SENSOR_PREARM_CHECK
    if not s.position_valid:
        health &= ~(px4.SENSOR_GPS | px4.SENSOR_XY_POSITION_CONTROL)
    voltage_mv, current_ca, remaining = (65535, -1, -1) if s.battery is None else (s.battery[1], NO_CURRENT_CA, s.battery[0])
    return mavlink.MAVLink_sys_status_message(SENSORS_PRESENT, SENSORS_PRESENT, health, 150, voltage_mv, current_ca,
                                              remaining, 0, 0, 0, 0, 0, 0, 0, 0, 0)


def battery_status(s: TelemetryState) -> Any | None:
    """PX4's BATTERY_STATUS of the simulated battery, as a PX4 SITL sends it (one pack, its voltage
    in the first cell field, no current sensor, nothing consumed); None without a battery (PX4
    publishes none)."""
    if s.battery is None:
        return None
    return mavlink.MAVLink_battery_status_message(0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LIPO,
                                                  32767, [s.battery[1]] + [65535] * 9, NO_CURRENT_CA, 0, -1,
                                                  s.battery[0], 0, mavlink.MAV_BATTERY_CHARGE_STATE_OK)


def extended_sys_state(s: TelemetryState) -> Any:
    return mavlink.MAVLink_extended_sys_state_message(0, s.landed_state)


def local_position_ned(s: TelemetryState, noisy: tuple[float, float, float], velocity: tuple[float, float, float]) -> Any:
    return mavlink.MAVLink_local_position_ned_message(_ms(s.t_s), *noisy, *velocity)


def global_position_int(s: TelemetryState, geo: Geo, noisy: tuple[float, float, float],
                        velocity: tuple[float, float, float]) -> Any:
    lat, lon, alt = geo.to_geodetic(*noisy)
    heading_cdeg = int(round(math.degrees(s.kin.yaw_rad) * 100.0)) % 36000
    return mavlink.MAVLink_global_position_int_message(
        _ms(s.t_s), int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000.0)),
        int(round((s.home_ned_m[2] - noisy[2]) * 1000.0)), _cm_s(velocity[0]), _cm_s(velocity[1]), _cm_s(velocity[2]), heading_cdeg)


def _cm_s(v_m_s: float) -> int:
    return max(-32768, min(32767, int(round(v_m_s * 100.0))))


def attitude(s: TelemetryState) -> Any:
    roll, pitch, yaw = attitude_rad(s.kin)
    return mavlink.MAVLink_attitude_message(_ms(s.t_s), roll, pitch, yaw, 0.0, 0.0, s.kin.yaw_rate_rad_s)


def attitude_quaternion(s: TelemetryState) -> Any:
    q = quaternion(*attitude_rad(s.kin))
    return mavlink.MAVLink_attitude_quaternion_message(_ms(s.t_s), *q, 0.0, 0.0, s.kin.yaw_rate_rad_s, [0.0] * 4)


def position_target_local_ned(s: TelemetryState) -> Any:
    """What PX4 streams: its position controller's own setpoint (the position in force, the
    velocity setpoint with the position loop's correction, the acceleration setpoint), NaN
    fields flagged in the mask. Before takeoff: the current position."""
    k, nan = s.kin, math.nan
    if not s.armed or k.on_ground:
        return mavlink.MAVLink_position_target_local_ned_message(_ms(s.t_s), px4.MAV_FRAME_LOCAL_NED, setpoints.TYPE_MASK_POSITION,
                                                                 k.n_m, k.e_m, k.d_m, nan, nan, nan, nan, nan, nan, k.yaw_rad, nan)
    sp = s.setpoint if s.mode == "OFFBOARD" else None
    position = sp.position if sp is not None else (nan, nan, nan)
    fields = (*position, *k.ctrl.velocity_sp, *k.ctrl.acceleration_sp)
    mask = sum(1 << i for i, value in enumerate(fields) if math.isnan(value))
    yaw = sp.yaw_rad if sp is not None and sp.yaw_rad is not None else k.yaw_rad
    yaw_rate = sp.yaw_rate_rad_s if sp is not None and sp.yaw_rate_rad_s is not None else 0.0
    return mavlink.MAVLink_position_target_local_ned_message(_ms(s.t_s), px4.MAV_FRAME_LOCAL_NED, mask, *fields, yaw, yaw_rate)


def attitude_target(s: TelemetryState) -> Any:
    """The attitude and collective thrust [0..1] the position controller asks for."""
    k = s.kin
    acc = k.ctrl.acceleration_sp
    cos_y, sin_y = math.cos(k.yaw_rad), math.sin(k.yaw_rad)
    roll = math.atan2(-sin_y * acc[0] + cos_y * acc[1], GRAVITY_M_S2)
    pitch = -math.atan2(cos_y * acc[0] + sin_y * acc[1], GRAVITY_M_S2)
    thrust = math.sqrt(sum(t * t for t in k.ctrl.thrust)) if s.armed and not k.on_ground else 0.0
    return mavlink.MAVLink_attitude_target_message(_ms(s.t_s), 0, quaternion(roll, pitch, k.yaw_rad), 0.0, 0.0,
                                                   k.yaw_rate_rad_s, thrust)


def odometry(s: TelemetryState, noisy: tuple[float, float, float], velocity: tuple[float, float, float]) -> Any:
    """PX4's ODOMETRY: pose and velocity in local NED (frame_id = child_frame_id = 1), with
    diagonal covariances (the off-diagonal entries NaN, as PX4 sends them)."""
    k, nan = s.kin, math.nan
    pose_cov = [nan] * 21
    for i, var in zip((0, 6, 11, 15, 18, 20), (0.04, 0.04, 0.09, 6e-5, 8e-5, 7e-4)):
        pose_cov[i] = var
    vel_cov = [nan] * 21
    for i in (0, 6, 11):
        vel_cov[i] = 0.009
    return mavlink.MAVLink_odometry_message(_us(s.t_s), px4.MAV_FRAME_LOCAL_NED, px4.MAV_FRAME_LOCAL_NED, *noisy,
                                            quaternion(*attitude_rad(k)), *velocity, 0.0, 0.0,
                                            k.yaw_rate_rad_s, pose_cov, vel_cov, 0, ESTIMATOR_TYPE_AUTOPILOT, 0)


def highres_imu(s: TelemetryState, geo: Geo) -> Any:
    """Specific force [m/s^2] and rates [rad/s] in body FRD, a magnetic field [gauss], and the
    static pressure [Pa, as PX4 sends it] of the standard atmosphere at the vehicle's altitude."""
    k = s.kin
    roll, pitch, yaw = attitude_rad(k)
    acc = _ned_to_body((k.an_m_s2, k.ae_m_s2, k.ad_m_s2 - GRAVITY_M_S2), roll, pitch, yaw)
    mag = _ned_to_body(EARTH_FIELD_NED_GAUSS, roll, pitch, yaw)
    alt = geo.alt0_m - k.d_m
    pressure_pa = 101325.0 * (1.0 - 2.25577e-5 * alt) ** 5.25588
    return mavlink.MAVLink_highres_imu_message(_us(s.t_s), *acc, 0.0, 0.0, k.yaw_rate_rad_s, *mag, pressure_pa, 0.0, alt,
                                               15.0, 0x1FF, 0)


def _ned_to_body(v: tuple[float, float, float], roll: float, pitch: float, yaw: float) -> tuple[float, float, float]:
    """A NED vector in the body FRD frame of the ZYX Euler angles."""
    cr, sr, cp, sp, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    x1, y1 = cy * v[0] + sy * v[1], -sy * v[0] + cy * v[1]  # yaw
    x2, z2 = cp * x1 - sp * v[2], sp * x1 + cp * v[2]  # pitch
    return x2, cr * y1 + sr * z2, -sr * y1 + cr * z2  # roll


def estimator_status(s: TelemetryState) -> Any:
    """EKF2's health: the flags PX4 SITL reports when healthy; none of the position ones once the
    position estimate is lost."""
    flags = ESTIMATOR_FLAGS_HEALTHY if s.position_valid else ESTIMATOR_FLAGS_ATTITUDE_ONLY
    return mavlink.MAVLink_estimator_status_message(_us(s.t_s), flags, 0.07, 0.02, 0.02, 0.09, 0.0, math.nan, 0.29, 0.30)


def altitude(s: TelemetryState, geo: Geo) -> Any:
    k = s.kin
    amsl = geo.alt0_m - k.d_m
    return mavlink.MAVLink_altitude_message(_us(s.t_s), amsl, amsl, -k.d_m, s.home_ned_m[2] - k.d_m,
                                            float("nan"), max(0.0, k.ground_d_m - k.d_m))


def vfr_hud(s: TelemetryState, geo: Geo) -> Any:
    k = s.kin
    speed = math.hypot(k.vn_m_s, k.ve_m_s)
    heading = int(round(math.degrees(k.yaw_rad))) % 360
    throttle = 0 if not s.armed else 50
    return mavlink.MAVLink_vfr_hud_message(speed, speed, heading, throttle, geo.alt0_m - k.d_m, -k.vd_m_s)


def home_position(s: TelemetryState, geo: Geo) -> Any:
    lat, lon, alt = geo.to_geodetic(*s.home_ned_m)
    return mavlink.MAVLink_home_position_message(int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000.0)),
                                                 *s.home_ned_m, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, _us(s.t_s))


def gps_global_origin(s: TelemetryState, geo: Geo) -> Any:
    return mavlink.MAVLink_gps_global_origin_message(int(round(geo.lat0_deg * 1e7)), int(round(geo.lon0_deg * 1e7)),
                                                     int(round(geo.alt0_m * 1000.0)), _us(s.t_s))


def distance_sensor(capture_t_s: float, range_m: float, sigma_m: float, max_range_m: float) -> Any:
    """A downward range as PX4 streams it (PX4-Autopilot src/modules/mavlink/streams/DISTANCE_SENSOR.hpp:
    ``time_boot_ms`` the sample's own timestamp, distances m -> cm, ``covariance`` the variance
    m^2 -> cm^2, ``signal_quality`` left 0, unknown; MAVLink common.xml DISTANCE_SENSOR: orientation
    MAV_SENSOR_ROTATION_PITCH_270 for downward, covariance UINT8_MAX if unknown): ``range_m`` [m]
    captured at ``capture_t_s`` [s of the vehicle's boot clock], ``sigma_m`` [m] its standard
    deviation (a variance over 254 cm^2 is sent as unknown), ``max_range_m`` [m] the sensor's
    reach (its minimum 0). The range is rounded to the centimetre, as on the wire."""
    variance_cm2 = (sigma_m * 100.0) ** 2
    covariance = int(round(variance_cm2)) if variance_cm2 < COVARIANCE_UNKNOWN - 0.5 else COVARIANCE_UNKNOWN
    return mavlink.MAVLink_distance_sensor_message(
        int(round(capture_t_s * 1000.0)) & 0xFFFFFFFF, 0, _cm(max_range_m), _cm(range_m),
        mavlink.MAV_DISTANCE_SENSOR_LASER, 0, DOWNWARD, covariance)


def _cm(m: float) -> int:
    return max(0, min(65535, int(round(m * 100.0))))


class RangeStream:
    """The mock vehicle's DISTANCE_SENSOR: its downward rangefinder (``cfg``, ``[world.rangefinder]``;
    None: no rangefinder, nothing is sent) with the in-process world's model
    (:mod:`sim.vehicle.physics.rangefinder`, draws from ``seed``), measuring at every physics step
    a capture is due from the true position down to the deck's top over its disc
    (:meth:`~sim.vehicle.physics.deck.Deck.top`, ``radius_m``), else the ground
    (:data:`GROUND_D_M`); each reading is sent ``latency_s`` after its capture (:func:`distance_sensor`)."""

    GROUND_D_M = 0.0  # beside the deck it sees the ground the physics lands on [m, NED down]

    def __init__(self, cfg: RangefinderSection | None, seed: int) -> None:
        self.sensor = None if cfg is None else Rangefinder(cfg, seed)
        self.sent = 0  # DISTANCE_SENSOR messages built (one per reading, whatever the links)

    @property
    def next_s(self) -> float:
        """When [s] the next held reading is due (inf: none)."""
        due = None if self.sensor is None else self.sensor.next_delivery_s()
        return math.inf if due is None else due

    def measure(self, t_s: float, kin: KinState, deck: Deck | None) -> None:
        """The physics step ending at ``t_s`` [s] left the vehicle at ``kin`` over ``deck`` (None: no deck)."""
        if self.sensor is None:
            return
        radius_m = 0.0 if deck is None else deck.spec.radius_m
        self.sensor.capture(t_s, lambda: range_below_m((kin.n_m, kin.e_m, kin.d_m), None if deck is None else deck.top(t_s),
                                                       radius_m, self.GROUND_D_M))  # the deck looked up only at a capture

    def due(self, t_s: float) -> list[Any]:
        """The DISTANCE_SENSOR messages of the readings due by ``t_s`` [s], in capture order, each once."""
        if self.sensor is None:
            return []
        c = self.sensor.cfg
        out = [distance_sensor(r.capture_t_s, r.range_m, c.sigma_m, c.max_range_m) for r in self.sensor.deliver(t_s)]
        self.sent += len(out)
        return out


def autopilot_version(sysid: int) -> Any:
    return mavlink.MAVLink_autopilot_version_message(CAPABILITIES, FLIGHT_SW_VERSION, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8,
                                                     0x26AC, 0x0011, 0x4D4F434B00000000 | sysid, [0] * 18)


def statustext_chunks(severity: int, text: str, chunk_id: int) -> list[Any]:
    """STATUSTEXT messages of ``text``: one if it fits in 50 bytes, else chunks sharing ``chunk_id``."""
    data = text.encode("utf-8", "replace")
    if len(data) <= 50:
        return [mavlink.MAVLink_statustext_message(severity, data, 0, 0)]
    pieces = [data[i:i + 50] for i in range(0, len(data), 50)]
    if len(pieces[-1]) == 50:
        pieces.append(b"")  # a final short chunk marks the end
    return [mavlink.MAVLink_statustext_message(severity, piece, chunk_id, seq) for seq, piece in enumerate(pieces)]


class PositionNoise:
    """What the reported state adds to the true one (never to the true state): seeded Gaussian
    noise [m] on the position and, when set, the estimate's errors ``estimate`` (position and
    velocity, :mod:`sim.vehicle.estimator`)."""

    def __init__(self, sigma_m: float, seed: int | None, estimate: EstimateError | None = None) -> None:
        self.sigma_m = float(sigma_m)
        self._rng = random.Random(None if seed is None else seed + 7919)
        self.estimate = estimate

    def apply(self, kin: KinState) -> tuple[float, float, float]:
        """The reported position [m] NED."""
        n, e, d = kin.n_m, kin.e_m, kin.d_m
        if self.estimate is not None:
            ep = self.estimate.position
            n, e, d = n + ep[0], e + ep[1], d + ep[2]
        if self.sigma_m <= 0.0:
            return n, e, d
        g = self._rng.gauss
        return n + g(0.0, self.sigma_m), e + g(0.0, self.sigma_m), d + g(0.0, self.sigma_m)

    def velocity(self, kin: KinState) -> tuple[float, float, float]:
        """The reported velocity [m/s] NED."""
        if self.estimate is None:
            return kin.vn_m_s, kin.ve_m_s, kin.vd_m_s
        ev = self.estimate.velocity
        return kin.vn_m_s + ev[0], kin.ve_m_s + ev[1], kin.vd_m_s + ev[2]


def build(name: str, s: TelemetryState, geo: Geo, noise: PositionNoise) -> Any | None:
    """The message of stream ``name`` for state ``s`` (None: nothing to send, as BATTERY_STATUS
    without a battery)."""
    if name == "HEARTBEAT":
        return heartbeat(s)
    if name == "LOCAL_POSITION_NED":
        return local_position_ned(s, noise.apply(s.kin), noise.velocity(s.kin))
    if name == "ODOMETRY":
        return odometry(s, noise.apply(s.kin), noise.velocity(s.kin))
    if name == "GLOBAL_POSITION_INT":
        return global_position_int(s, geo, noise.apply(s.kin), noise.velocity(s.kin))
    if name in _GEO_BUILDERS:
        return _GEO_BUILDERS[name](s, geo)
    return _PLAIN_BUILDERS[name](s)


_GEO_BUILDERS = {"ALTITUDE": altitude, "VFR_HUD": vfr_hud, "HOME_POSITION": home_position, "GPS_GLOBAL_ORIGIN": gps_global_origin,
                 "HIGHRES_IMU": highres_imu}
_PLAIN_BUILDERS = {"SYS_STATUS": sys_status, "BATTERY_STATUS": battery_status, "EXTENDED_SYS_STATE": extended_sys_state, "ATTITUDE": attitude,
                   "ATTITUDE_QUATERNION": attitude_quaternion, "POSITION_TARGET_LOCAL_NED": position_target_local_ned,
                   "ATTITUDE_TARGET": attitude_target, "ESTIMATOR_STATUS": estimator_status}
