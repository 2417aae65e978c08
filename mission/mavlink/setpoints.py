"""Setpoint messages as PX4 reads them in OFFBOARD (pure: values in, pymavlink message out)."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from mission.mavlink import px4
from mission.mavlink.env import mavlink

FLOAT32_MAX = float(np.finfo(np.float32).max)


def checked_velocity(v_ned_m_s: Any, yaw_rad: float | None) -> tuple[float, float, float]:
    """The velocity [m/s] as three floats; ValueError for a wrong shape or a non-finite (or
    float32-overflowing) velocity or yaw [rad]."""
    v = np.asarray(v_ned_m_s, dtype=float)
    if v.shape != (3,):
        raise ValueError(f"velocity must have shape (3,), got {v.shape}")
    vn, ve, vd = v.tolist()  # three Python floats: checked faster than with numpy reductions
    if not all(math.isfinite(c) and abs(c) <= FLOAT32_MAX for c in (vn, ve, vd)):
        raise ValueError(f"refusing non-finite velocity setpoint {[vn, ve, vd]}")
    if yaw_rad is not None and not (math.isfinite(yaw_rad) and abs(yaw_rad) <= FLOAT32_MAX):
        raise ValueError(f"refusing non-finite yaw {yaw_rad!r}")
    return vn, ve, vd


def velocity_ned_message(target: tuple[int, int], velocity: tuple[float, float, float], yaw_rad: float | None,
                         time_boot_ms: int) -> Any:
    """SET_POSITION_TARGET_LOCAL_NED in LOCAL_NED (frame 1): velocity only (type mask 3527) or
    velocity + yaw (2503), to ``target`` (system, component)."""
    mask = px4.TYPE_MASK_VELOCITY if yaw_rad is None else px4.TYPE_MASK_VELOCITY_YAW
    vn, ve, vd = velocity
    return mavlink.MAVLink_set_position_target_local_ned_message(
        time_boot_ms & 0xFFFFFFFF, target[0], target[1], mavlink.MAV_FRAME_LOCAL_NED, mask,
        0.0, 0.0, 0.0, vn, ve, vd, 0.0, 0.0, 0.0, 0.0 if yaw_rad is None else float(yaw_rad), 0.0,
    )


def checked_vectors(**vectors: Any) -> list[float]:
    """The vectors' components in order, as floats; ValueError naming the vector for a wrong shape
    or a non-finite (or float32-overflowing) component."""
    values: list[float] = []
    for name, vec in vectors.items():
        v = np.asarray(vec, dtype=float)
        if v.shape != (3,):
            raise ValueError(f"{name} must have shape (3,), got {v.shape}")
        parts = v.tolist()
        if not all(math.isfinite(c) and abs(c) <= FLOAT32_MAX for c in parts):
            raise ValueError(f"refusing non-finite {name} setpoint {parts}")
        values += parts
    return values


def full_setpoint_message(target: tuple[int, int], values: list[float], time_boot_ms: int) -> Any:
    """SET_POSITION_TARGET_LOCAL_NED in LOCAL_NED with position [m], velocity [m/s] and acceleration
    [m/s^2] (``values``, 9 floats; type mask 3072: yaw and yaw rate ignored). Bit 512 is never set:
    PX4 reads it as *force* and drops the setpoint."""
    return mavlink.MAVLink_set_position_target_local_ned_message(
        time_boot_ms & 0xFFFFFFFF, target[0], target[1], mavlink.MAV_FRAME_LOCAL_NED,
        px4.TYPE_MASK_POSITION_VELOCITY_ACCELERATION, *values, 0.0, 0.0)
