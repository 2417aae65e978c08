"""SET_POSITION_TARGET_LOCAL_NED: the one MAVLink encoding of a setpoint, and its decoding (pure).

:func:`encode` turns a :class:`~mission.core.setpoint.Setpoint` into the message PX4 reads in
OFFBOARD; :func:`decode_target` reads any such message as PX4's ``mavlink_receiver`` does (the
mock vehicle decodes through it); :func:`decode` is the exact inverse of :func:`encode`. All three
read the one table of type-mask bits below, so the encoder and the decoders cannot drift.

The type mask (POSITION_TARGET_TYPEMASK) has one *ignore* bit per field. What we send:

====================  =========  ==========================================================
setpoint              type_mask  fields
====================  =========  ==========================================================
velocity only         3527       velocity [m/s]
velocity + yaw        2503       velocity [m/s], yaw [rad]
full                  3072       position [m], velocity [m/s], acceleration [m/s^2]
full + yaw            2048       the same and yaw [rad]
full, horizontal      3332       position and acceleration north and east, velocity [m/s]
full, vertical        3267       position and acceleration down, velocity [m/s]
====================  =========  ==========================================================

A full setpoint on some axes only (:attr:`Setpoint.position_axes`) sets the position and
acceleration ignore bits of the others: PX4's receiver reads those fields as NaN, per axis, and
its position controller adds a position or acceleration term only where it is finite
(``mavlink_receiver.cpp`` ``handle_message_set_position_target_local_ned``;
``PositionControl::_inputValid`` wants north and east together). The yaw bits combine as above.

Bit 512 (FORCE_SET) is never set: PX4 reads the acceleration as a *force* then and drops the
setpoint. Frame: always LOCAL_NED (1). Ignored fields are sent as 0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from mission.core.setpoint import Setpoint
from mission.mavlink import px4
from mission.mavlink.env import mavlink

FLOAT32_MAX = float(np.finfo(np.float32).max)

# POSITION_TARGET_TYPEMASK: a set bit ignores its field
X_IGNORE, Y_IGNORE, Z_IGNORE = 1, 2, 4
VX_IGNORE, VY_IGNORE, VZ_IGNORE = 8, 16, 32
AX_IGNORE, AY_IGNORE, AZ_IGNORE = 64, 128, 256
FORCE_SET = 512
YAW_IGNORE, YAW_RATE_IGNORE = 1024, 2048
POSITION_IGNORE = X_IGNORE | Y_IGNORE | Z_IGNORE
VELOCITY_IGNORE = VX_IGNORE | VY_IGNORE | VZ_IGNORE
ACCELERATION_IGNORE = AX_IGNORE | AY_IGNORE | AZ_IGNORE

# Named masks: ours (see the table above) and the ones other clients send (MAVSDK), which the mock
# vehicle and the tests speak
TYPE_MASK_VELOCITY = POSITION_IGNORE | ACCELERATION_IGNORE | YAW_IGNORE | YAW_RATE_IGNORE  # 3527
TYPE_MASK_VELOCITY_YAW = POSITION_IGNORE | ACCELERATION_IGNORE | YAW_RATE_IGNORE  # 2503 (MAVSDK set_velocity_ned)
TYPE_MASK_VELOCITY_YAW_RATE = POSITION_IGNORE | ACCELERATION_IGNORE | YAW_IGNORE  # 1479 (MAVSDK set_velocity_body)
TYPE_MASK_POSITION = VELOCITY_IGNORE | ACCELERATION_IGNORE | YAW_RATE_IGNORE  # 2552: position (+ yaw)
TYPE_MASK_POSITION_VELOCITY_ACCELERATION = YAW_IGNORE | YAW_RATE_IGNORE  # 3072


AXIS_IGNORE = ((X_IGNORE | AX_IGNORE), (Y_IGNORE | AY_IGNORE), (Z_IGNORE | AZ_IGNORE))  # north, east, down


def type_mask(setpoint: Setpoint) -> int:
    """The type mask that sends exactly the setpoint's fields (never a yaw rate, never FORCE_SET)."""
    mask = YAW_RATE_IGNORE
    if not setpoint.full:
        mask |= POSITION_IGNORE | ACCELERATION_IGNORE
    else:
        for bits, sent in zip(AXIS_IGNORE, setpoint.position_axes):
            mask |= 0 if sent else bits
    if setpoint.yaw_rad is None:
        mask |= YAW_IGNORE
    return mask


def _checked(name: str, vec: np.ndarray | None) -> list[float]:
    """The vector's three components as floats (zeros when absent: an ignored field); ValueError
    naming the field for a non-finite or float32-overflowing one."""
    if vec is None:
        return [0.0, 0.0, 0.0]
    parts = vec.tolist()  # three Python floats: checked faster than with numpy reductions
    if not all(math.isfinite(c) and abs(c) <= FLOAT32_MAX for c in parts):
        raise ValueError(f"refusing non-finite {name} setpoint {parts}")
    return parts


def encode(setpoint: Setpoint, target: tuple[int, int], time_boot_ms: int) -> Any:
    """SET_POSITION_TARGET_LOCAL_NED of ``setpoint`` to ``target`` (system, component), in
    LOCAL_NED with :func:`type_mask`. ValueError naming the field for a non-finite (or
    float32-overflowing) component or yaw, before any message exists."""
    position = _checked("position", setpoint.position_ned_m)
    velocity = _checked("velocity", setpoint.velocity_ned_m_s)
    acceleration = _checked("acceleration", setpoint.acceleration_ned_m_s2)
    if setpoint.full and not all(setpoint.position_axes):  # ignored fields go as 0
        position = [c if sent else 0.0 for c, sent in zip(position, setpoint.position_axes)]
        acceleration = [c if sent else 0.0 for c, sent in zip(acceleration, setpoint.position_axes)]
    yaw = setpoint.yaw_rad
    if yaw is not None and not (math.isfinite(yaw) and abs(yaw) <= FLOAT32_MAX):
        raise ValueError(f"refusing non-finite yaw {yaw!r}")
    return mavlink.MAVLink_set_position_target_local_ned_message(
        time_boot_ms & 0xFFFFFFFF, target[0], target[1], px4.MAV_FRAME_LOCAL_NED, type_mask(setpoint),
        *position, *velocity, *acceleration, 0.0 if yaw is None else yaw, 0.0)


@dataclass(frozen=True)
class Target:
    """A SET_POSITION_TARGET_LOCAL_NED as PX4's receiver reads its fields: each component is NaN
    when its ignore bit is set, else taken as sent (NaN or inf included); yaw [rad] and yaw rate
    [rad/s] None when ignored or not finite. The frame is not interpreted (a BODY_NED reader
    rotates velocity and acceleration itself). Position [m], velocity [m/s], acceleration [m/s^2]."""

    frame: int
    type_mask: int
    position: tuple[float, float, float]
    velocity: tuple[float, float, float]
    acceleration: tuple[float, float, float]
    yaw_rad: float | None
    yaw_rate_rad_s: float | None

    @property
    def force(self) -> bool:
        """FORCE_SET: the acceleration would be a force (PX4 drops such a setpoint)."""
        return bool(self.type_mask & FORCE_SET)


def decode_target(msg: Any) -> Target:
    """The fields of a SET_POSITION_TARGET_LOCAL_NED ``msg`` as PX4 reads them (:class:`Target`)."""
    mask = int(msg.type_mask)

    def field(bit: int, value: float) -> float:
        return math.nan if mask & bit else float(value)

    def angle(bit: int, value: float) -> float | None:
        return None if mask & bit or not math.isfinite(value) else float(value)

    return Target(
        int(msg.coordinate_frame), mask,
        (field(X_IGNORE, msg.x), field(Y_IGNORE, msg.y), field(Z_IGNORE, msg.z)),
        (field(VX_IGNORE, msg.vx), field(VY_IGNORE, msg.vy), field(VZ_IGNORE, msg.vz)),
        (field(AX_IGNORE, msg.afx), field(AY_IGNORE, msg.afy), field(AZ_IGNORE, msg.afz)),
        angle(YAW_IGNORE, msg.yaw), angle(YAW_RATE_IGNORE, msg.yaw_rate))


def decode(msg: Any) -> Setpoint:
    """The setpoint :func:`encode` made ``msg`` from (values as float32 carried them). ValueError
    for a message no setpoint encodes to: another frame, or a type mask :func:`type_mask` never gives."""
    t = decode_target(msg)
    if t.frame != px4.MAV_FRAME_LOCAL_NED:
        raise ValueError(f"setpoint frame {t.frame} is not LOCAL_NED ({px4.MAV_FRAME_LOCAL_NED})")
    axes = tuple(not t.type_mask & bit for bit in (X_IGNORE, Y_IGNORE, Z_IGNORE))
    full = any(axes)
    if full and (axes[0] != axes[1]):
        raise ValueError(f"type_mask {t.type_mask} sends one horizontal position axis without the other")
    setpoint = Setpoint(np.array(t.velocity), np.nan_to_num(np.array(t.position)) if full else None,
                        np.nan_to_num(np.array(t.acceleration)) if full else None, t.yaw_rad,
                        axes if full else (True, True, True))  # type: ignore[arg-type]
    if type_mask(setpoint) != t.type_mask:
        raise ValueError(f"type_mask {t.type_mask} is no setpoint kind (nearest: {type_mask(setpoint)})")
    return setpoint
