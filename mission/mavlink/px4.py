"""PX4's own MAVLink encodings, shared by the link (client) and the mock vehicle (server).

PX4's mode encoding (``custom_mode``, the modes' ``base_mode`` flags, the offboard-loss actions),
its parameter encoding (an INT32 parameter's bits carried in PARAM_VALUE's and PARAM_SET's float
field: "bytewise", reinterpreted, never converted; a REAL32 as the float) and the setpoint type
masks PX4 and MAVSDK use, as PX4 main (2026) and a real PX4 SITL on the
wire show them. Pure constants and encoders; no I/O. The MAVLink numbers below the modes are
the pymavlink dialect's (one source): new code reads them from
:data:`mission.mavlink.env.mavlink` directly.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

from mission.flight_mode import MANUAL_MODES, FlightMode
from mission.passenger.target import LandingTarget
from mission.vision.frames import euler_quaternion
from mission.mavlink.env import mavlink


class MainMode(IntEnum):
    MANUAL = 1
    ALTCTL = 2
    POSCTL = 3
    AUTO = 4
    ACRO = 5
    OFFBOARD = 6
    STABILIZED = 7


class AutoSubMode(IntEnum):
    READY = 1
    TAKEOFF = 2
    LOITER = 3
    MISSION = 4
    RTL = 5
    LAND = 6
    FOLLOW_TARGET = 8
    PRECLAND = 9


def encode_custom_mode(main: int, sub: int = 0) -> int:
    """HEARTBEAT.custom_mode = (main << 16) | (sub << 24)."""
    return (int(main) << 16) | (int(sub) << 24)


def decode_custom_mode(custom_mode: int) -> tuple[int, int]:
    """Inverse of :func:`encode_custom_mode`: (main mode, sub mode)."""
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


# Each named mode as its (main, sub) pair.
MODES: dict[FlightMode, tuple[int, int]] = {
    FlightMode.MANUAL: (MainMode.MANUAL, 0),
    FlightMode.ALTCTL: (MainMode.ALTCTL, 0),
    FlightMode.POSCTL: (MainMode.POSCTL, 0),
    FlightMode.OFFBOARD: (MainMode.OFFBOARD, 0),
    FlightMode.STABILIZED: (MainMode.STABILIZED, 0),
    FlightMode.ACRO: (MainMode.ACRO, 0),
    FlightMode.READY: (MainMode.AUTO, AutoSubMode.READY),
    FlightMode.TAKEOFF: (MainMode.AUTO, AutoSubMode.TAKEOFF),
    FlightMode.HOLD: (MainMode.AUTO, AutoSubMode.LOITER),
    FlightMode.MISSION: (MainMode.AUTO, AutoSubMode.MISSION),
    FlightMode.RTL: (MainMode.AUTO, AutoSubMode.RTL),
    FlightMode.LAND: (MainMode.AUTO, AutoSubMode.LAND),
}
HOLD = FlightMode.HOLD


def mode_name(custom_mode: int) -> str:
    """Readable PX4 mode name of a HEARTBEAT custom_mode (``"UNKNOWN(0x..)"`` otherwise)."""
    pair = decode_custom_mode(custom_mode)
    for name, (main, sub) in MODES.items():
        if (int(main), int(sub)) == pair:
            return name
    return f"UNKNOWN(0x{custom_mode:08x})"


def custom_mode_of(name: str) -> int:
    """HEARTBEAT.custom_mode of the mode ``name`` (a :class:`FlightMode` or its name)."""
    main, sub = MODES[FlightMode(name)]
    return encode_custom_mode(main, sub)


# COM_OBL_RC_ACT value -> mode entered on offboard loss (6 Terminate, 7 Disarm handled apart).
OFFBOARD_LOSS_ACTION_MODE = {0: FlightMode.POSCTL, 1: FlightMode.ALTCTL, 2: FlightMode.STABILIZED, 3: FlightMode.RTL,
                             4: FlightMode.LAND, 5: FlightMode.HOLD}

# HEARTBEAT
MAV_AUTOPILOT_PX4 = mavlink.MAV_AUTOPILOT_PX4
MAV_TYPE_QUADROTOR = mavlink.MAV_TYPE_QUADROTOR
MAV_TYPE_GROUND_ROVER = mavlink.MAV_TYPE_GROUND_ROVER
MAV_TYPE_ONBOARD_CONTROLLER = mavlink.MAV_TYPE_ONBOARD_CONTROLLER
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
MAV_MODE_FLAG_SAFETY_ARMED = mavlink.MAV_MODE_FLAG_SAFETY_ARMED
MAV_STATE_STANDBY = mavlink.MAV_STATE_STANDBY
MAV_STATE_ACTIVE = mavlink.MAV_STATE_ACTIVE
MAV_STATE_CRITICAL = mavlink.MAV_STATE_CRITICAL

# Commands and results
MAV_CMD_DO_SET_MODE = mavlink.MAV_CMD_DO_SET_MODE
MAV_CMD_COMPONENT_ARM_DISARM = mavlink.MAV_CMD_COMPONENT_ARM_DISARM
MAV_CMD_NAV_TAKEOFF = mavlink.MAV_CMD_NAV_TAKEOFF
MAV_CMD_NAV_LAND = mavlink.MAV_CMD_NAV_LAND
MAV_CMD_NAV_RETURN_TO_LAUNCH = mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
MAV_CMD_REQUEST_MESSAGE = mavlink.MAV_CMD_REQUEST_MESSAGE
MAV_CMD_SET_MESSAGE_INTERVAL = mavlink.MAV_CMD_SET_MESSAGE_INTERVAL
MAV_CMD_GET_MESSAGE_INTERVAL = mavlink.MAV_CMD_GET_MESSAGE_INTERVAL
ARM_FORCE_MAGIC = 21196
MAV_RESULT_ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
MAV_RESULT_TEMPORARILY_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
MAV_RESULT_DENIED = mavlink.MAV_RESULT_DENIED
MAV_RESULT_UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED
MAV_RESULT_FAILED = mavlink.MAV_RESULT_FAILED

# SET_POSITION_TARGET_LOCAL_NED frames (the type masks: mission.mavlink.setpoints)
MAV_FRAME_LOCAL_NED = mavlink.MAV_FRAME_LOCAL_NED
MAV_FRAME_BODY_NED = mavlink.MAV_FRAME_BODY_NED

# EXTENDED_SYS_STATE.landed_state
LANDED_ON_GROUND = mavlink.MAV_LANDED_STATE_ON_GROUND
LANDED_IN_AIR = mavlink.MAV_LANDED_STATE_IN_AIR
LANDED_TAKEOFF = mavlink.MAV_LANDED_STATE_TAKEOFF
LANDED_LANDING = mavlink.MAV_LANDED_STATE_LANDING

# HEARTBEAT.base_mode flags beyond CUSTOM_MODE_ENABLED and SAFETY_ARMED, as PX4 sets them
# (a PX4 SITL sends: Hold disarmed 29, OFFBOARD armed 145, POSCTL armed 209).
MAV_MODE_FLAG_AUTO_ENABLED = mavlink.MAV_MODE_FLAG_AUTO_ENABLED
MAV_MODE_FLAG_GUIDED_ENABLED = mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
MAV_MODE_FLAG_STABILIZE_ENABLED = mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
MAV_MODE_FLAG_MANUAL_INPUT_ENABLED = mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED


def base_mode_of(name: str, armed: bool) -> int:
    """HEARTBEAT.base_mode that PX4 reports for mode ``name`` (a key of :data:`MODES`)."""
    flags = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if name.startswith("AUTO."):
        flags |= MAV_MODE_FLAG_AUTO_ENABLED | MAV_MODE_FLAG_GUIDED_ENABLED | MAV_MODE_FLAG_STABILIZE_ENABLED
    elif name in MANUAL_MODES:
        flags |= MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        if name not in (FlightMode.MANUAL, FlightMode.ACRO):
            flags |= MAV_MODE_FLAG_STABILIZE_ENABLED
    else:  # OFFBOARD
        flags |= MAV_MODE_FLAG_STABILIZE_ENABLED
    if armed:
        flags |= MAV_MODE_FLAG_SAFETY_ARMED
    return flags


# SYS_STATUS onboard_control_sensors_* bits (MAV_SYS_STATUS_SENSOR)
SENSOR_3D_GYRO = mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO
SENSOR_3D_ACCEL = mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
SENSOR_3D_MAG = mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG
SENSOR_ABSOLUTE_PRESSURE = mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
SENSOR_GPS = mavlink.MAV_SYS_STATUS_SENSOR_GPS
SENSOR_ANGULAR_RATE_CONTROL = mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
SENSOR_ATTITUDE_STABILIZATION = mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
SENSOR_YAW_POSITION = mavlink.MAV_SYS_STATUS_SENSOR_YAW_POSITION
SENSOR_Z_ALTITUDE_CONTROL = mavlink.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
SENSOR_XY_POSITION_CONTROL = mavlink.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
SENSOR_MOTOR_OUTPUTS = mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
SENSOR_AHRS = mavlink.MAV_SYS_STATUS_AHRS
SENSOR_PREARM_CHECK = mavlink.MAV_SYS_STATUS_PREARM_CHECK
SYS_STATUS_EXTENSION_USED = mavlink.MAV_SYS_STATUS_EXTENSION_USED  # PX4 ORs this into present/enabled/health

# Messages, parameters, STATUSTEXT
MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES = mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES
MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT = mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT = mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
MAV_PROTOCOL_CAPABILITY_MISSION_INT = mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
MAV_PROTOCOL_CAPABILITY_COMMAND_INT = mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED = mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT = mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
MAV_PROTOCOL_CAPABILITY_MAVLINK2 = mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
MAV_PARAM_TYPE_INT32 = mavlink.MAV_PARAM_TYPE_INT32
MAV_PARAM_TYPE_REAL32 = mavlink.MAV_PARAM_TYPE_REAL32
MAV_SEVERITY_CRITICAL = mavlink.MAV_SEVERITY_CRITICAL
MAV_SEVERITY_WARNING = mavlink.MAV_SEVERITY_WARNING
MAV_SEVERITY_INFO = mavlink.MAV_SEVERITY_INFO


# ---- parameters


def pack_int32(value: int) -> float:
    """The float32 whose bits are the int32 ``value`` (PX4's bytewise PARAM_VALUE encoding)."""
    return struct.unpack("<f", struct.pack("<i", int(value)))[0]


def unpack_int32(encoded: float) -> int:
    """Inverse of :func:`pack_int32`."""
    return struct.unpack("<i", struct.pack("<f", encoded))[0]


def decode_param(wire_value: float, param_type: int) -> float:
    """A PARAM_VALUE's value: integer types unpacked from the float's bits, mavlink.MAV_PARAM_TYPE_REAL32 as it is."""
    return wire_value if param_type == mavlink.MAV_PARAM_TYPE_REAL32 else float(unpack_int32(wire_value))


def encode_param(value: float, param_type: int) -> float:
    """PARAM_SET's float field for ``value`` of ``param_type`` (integers rounded, then packed)."""
    return float(value) if param_type == mavlink.MAV_PARAM_TYPE_REAL32 else pack_int32(int(round(value)))


# LANDING_TARGET (docs/px4-precland.md). PX4's ``handle_message_landing_target`` reads only
# ``position_valid``, ``frame``, ``time_usec`` and x, y, z of a position-valid message: its
# ``landing_target_pose`` gets x_abs, y_abs, z_abs (its local NED frame [m]) with abs_pos_valid,
# stamped with time_usec moved onto its clock once its TIMESYNC on that link has converged,
# else with the arrival time; q, type and target_num are not read. position_valid 0 is read as an
# IR-LOCK report (the image angles): never sent.
FLOAT32_MAX = 3.4028234663852886e38  # float32's largest finite value


def encode_landing_target(target: LandingTarget) -> Any:
    """LANDING_TARGET of ``target`` as PX4 accepts it: position_valid 1, frame LOCAL_NED, type
    VISION_FIDUCIAL, target_num 0, the image fields (angles, distance, sizes) 0. ValueError for a
    coordinate beyond float32, before any message exists."""
    x, y, z = target.position_ned_m
    if not all(math.isfinite(c) and abs(c) <= FLOAT32_MAX for c in (x, y, z)):
        raise ValueError(f"refusing landing target {target.position_ned_m}")
    return mavlink.MAVLink_landing_target_message(
        target.time_usec & 0xFFFFFFFFFFFFFFFF, 0, MAV_FRAME_LOCAL_NED, 0.0, 0.0, 0.0, 0.0, 0.0,
        x, y, z, [float(c) for c in euler_quaternion(0.0, 0.0, target.yaw_rad or 0.0)],
        mavlink.LANDING_TARGET_TYPE_VISION_FIDUCIAL, 1)


@dataclass(frozen=True)
class LandingTargetReading:
    """What PX4's ``handle_message_landing_target`` makes of a LANDING_TARGET: ``kind`` is
    ``"pose"`` (a ``landing_target_pose`` with ``abs_pos_valid`` and ``position_ned_m`` =
    x, y, z [m] as float32 carried them), ``"unsupported_frame"`` (position-valid in another
    frame: refused with a critical STATUSTEXT naming ``frame``) or ``"irlock"`` (position_valid
    0: an IR-LOCK report of the image angles, which only PX4's landing_target_estimator reads)."""

    kind: str
    frame: int
    position_ned_m: tuple[float, float, float] | None
    time_usec: int


def landing_target_reading(msg: Any) -> LandingTargetReading:
    """Read ``msg`` (a LANDING_TARGET) as PX4's receiver does: see :class:`LandingTargetReading`."""
    frame, t = int(msg.frame), int(msg.time_usec)
    if msg.position_valid and frame == MAV_FRAME_LOCAL_NED:
        return LandingTargetReading("pose", frame, (float(msg.x), float(msg.y), float(msg.z)), t)
    return LandingTargetReading("unsupported_frame" if msg.position_valid else "irlock", frame, None, t)
