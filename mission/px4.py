"""PX4 MAVLink protocol facts shared by the link (client) and the mock vehicle (server).

Pure constants and encoders; no I/O. Sources: ../shared/REFERENCE.md (PX4 main, 2026, and what a
real PX4 SITL was seen to do on the wire).
"""
from __future__ import annotations

from enum import IntEnum


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


# Named modes as (main, sub) pairs and their names as pymavlink's interpret_px4_mode prints them.
MODES: dict[str, tuple[int, int]] = {
    "MANUAL": (MainMode.MANUAL, 0),
    "ALTCTL": (MainMode.ALTCTL, 0),
    "POSCTL": (MainMode.POSCTL, 0),
    "OFFBOARD": (MainMode.OFFBOARD, 0),
    "STABILIZED": (MainMode.STABILIZED, 0),
    "ACRO": (MainMode.ACRO, 0),
    "AUTO.READY": (MainMode.AUTO, AutoSubMode.READY),
    "AUTO.TAKEOFF": (MainMode.AUTO, AutoSubMode.TAKEOFF),
    "AUTO.LOITER": (MainMode.AUTO, AutoSubMode.LOITER),
    "AUTO.MISSION": (MainMode.AUTO, AutoSubMode.MISSION),
    "AUTO.RTL": (MainMode.AUTO, AutoSubMode.RTL),
    "AUTO.LAND": (MainMode.AUTO, AutoSubMode.LAND),
}
HOLD = "AUTO.LOITER"


def mode_name(custom_mode: int) -> str:
    """Readable PX4 mode name of a HEARTBEAT custom_mode (``"UNKNOWN(0x..)"`` otherwise)."""
    pair = decode_custom_mode(custom_mode)
    for name, (main, sub) in MODES.items():
        if (int(main), int(sub)) == pair:
            return name
    return f"UNKNOWN(0x{custom_mode:08x})"


def custom_mode_of(name: str) -> int:
    main, sub = MODES[name]
    return encode_custom_mode(main, sub)


# COM_OBL_RC_ACT value -> mode entered on offboard loss (6 Terminate, 7 Disarm handled apart).
OFFBOARD_LOSS_ACTION_MODE = {0: "POSCTL", 1: "ALTCTL", 2: "STABILIZED", 3: "AUTO.RTL", 4: "AUTO.LAND", 5: "AUTO.LOITER"}

# HEARTBEAT
MAV_AUTOPILOT_PX4 = 12
MAV_TYPE_QUADROTOR = 2
MAV_TYPE_GROUND_ROVER = 10
MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_STATE_STANDBY = 3
MAV_STATE_ACTIVE = 4
MAV_STATE_CRITICAL = 5

# Commands and results
MAV_CMD_DO_SET_MODE = 176
MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_NAV_LAND = 21
MAV_CMD_NAV_RETURN_TO_LAUNCH = 20
MAV_CMD_REQUEST_MESSAGE = 512
MAV_CMD_SET_MESSAGE_INTERVAL = 511
ARM_FORCE_MAGIC = 21196
MAV_RESULT_ACCEPTED = 0
MAV_RESULT_TEMPORARILY_REJECTED = 1
MAV_RESULT_DENIED = 2
MAV_RESULT_UNSUPPORTED = 3
MAV_RESULT_FAILED = 4

# SET_POSITION_TARGET_LOCAL_NED
MAV_FRAME_LOCAL_NED = 1
MAV_FRAME_BODY_NED = 8
TYPE_MASK_VELOCITY = 0x0DC7  # 3527: velocity only
TYPE_MASK_VELOCITY_YAW = 2503  # velocity + yaw (MAVSDK set_velocity_ned)
TYPE_MASK_VELOCITY_YAW_RATE = 1479  # velocity + yaw rate (MAVSDK set_velocity_body)
TYPE_MASK_POSITION = 2552

# EXTENDED_SYS_STATE.landed_state
LANDED_ON_GROUND = 1
LANDED_IN_AIR = 2
LANDED_TAKEOFF = 3
LANDED_LANDING = 4

# HEARTBEAT.base_mode flags beyond CUSTOM_MODE_ENABLED and SAFETY_ARMED, as PX4 sets them
# (seen on SITL: Hold disarmed 29, OFFBOARD armed 145, POSCTL armed 209).
MAV_MODE_FLAG_AUTO_ENABLED = 4
MAV_MODE_FLAG_GUIDED_ENABLED = 8
MAV_MODE_FLAG_STABILIZE_ENABLED = 16
MAV_MODE_FLAG_MANUAL_INPUT_ENABLED = 64
MANUAL_MODES = frozenset({"MANUAL", "ALTCTL", "POSCTL", "STABILIZED", "ACRO"})


def base_mode_of(name: str, armed: bool) -> int:
    """HEARTBEAT.base_mode that PX4 reports for mode ``name`` (a key of :data:`MODES`)."""
    flags = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if name.startswith("AUTO."):
        flags |= MAV_MODE_FLAG_AUTO_ENABLED | MAV_MODE_FLAG_GUIDED_ENABLED | MAV_MODE_FLAG_STABILIZE_ENABLED
    elif name in MANUAL_MODES:
        flags |= MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        if name not in ("MANUAL", "ACRO"):
            flags |= MAV_MODE_FLAG_STABILIZE_ENABLED
    else:  # OFFBOARD
        flags |= MAV_MODE_FLAG_STABILIZE_ENABLED
    if armed:
        flags |= MAV_MODE_FLAG_SAFETY_ARMED
    return flags


# SYS_STATUS onboard_control_sensors_* bits (MAV_SYS_STATUS_SENSOR)
SENSOR_3D_GYRO = 1 << 0
SENSOR_3D_ACCEL = 1 << 1
SENSOR_3D_MAG = 1 << 2
SENSOR_ABSOLUTE_PRESSURE = 1 << 3
SENSOR_GPS = 1 << 5
SENSOR_ANGULAR_RATE_CONTROL = 1 << 10
SENSOR_ATTITUDE_STABILIZATION = 1 << 11
SENSOR_YAW_POSITION = 1 << 12
SENSOR_Z_ALTITUDE_CONTROL = 1 << 13
SENSOR_XY_POSITION_CONTROL = 1 << 14
SENSOR_MOTOR_OUTPUTS = 1 << 15
SENSOR_AHRS = 1 << 21
SENSOR_PREARM_CHECK = 1 << 28
SYS_STATUS_EXTENSION_USED = 0x80000000  # PX4 ORs this into present/enabled/health

# Messages, parameters, STATUSTEXT
MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES = 520
MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT = 1 << 0
MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT = 1 << 1
MAV_PROTOCOL_CAPABILITY_MISSION_INT = 1 << 2
MAV_PROTOCOL_CAPABILITY_COMMAND_INT = 1 << 3
MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED = 1 << 7
MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT = 1 << 8
MAV_PROTOCOL_CAPABILITY_MAVLINK2 = 1 << 13
MAV_PARAM_TYPE_INT32 = 6
MAV_PARAM_TYPE_REAL32 = 9
MAV_SEVERITY_CRITICAL = 2
MAV_SEVERITY_WARNING = 4
MAV_SEVERITY_INFO = 6
