"""Pure MAVLink decoding rules of the mock vehicle: what PX4 makes of a command or a setpoint.

No I/O and no state: message fields in, a decision out (a mode name, a :class:`Setpoint` in
local NED, or None when PX4 would drop the message).
"""
from __future__ import annotations

import math
from typing import Any

from mission.mavlink import px4
from mission.mavlink.env import mavlink
from sim.vehicle.modes import Setpoint
from sim.vehicle.params import ParamTable
from sim.vehicle.physics.multicopter import body_to_ned

# type_mask bits (MAVLink POSITION_TARGET_TYPEMASK)
X_IGNORE, Y_IGNORE, Z_IGNORE, VX_IGNORE, VY_IGNORE, VZ_IGNORE = 1, 2, 4, 8, 16, 32
AX_IGNORE, AY_IGNORE, AZ_IGNORE, FORCE_SET, YAW_IGNORE, YAW_RATE_IGNORE = 64, 128, 256, 512, 1024, 2048
NAN = math.nan


def int_param(value: float) -> int:
    """A command parameter as an int; NaN (unused, as MAVSDK sends them) reads as 0."""
    return int(round(value)) if math.isfinite(value) else 0


def mode_of_set_mode(params: list[float]) -> str | None:
    """The mode name a DO_SET_MODE asks for (param1 base mode with CUSTOM_MODE_ENABLED, param2
    main mode, param3 sub mode, each cast to uint8), or None if PX4 has no such mode. The sub
    mode only matters for AUTO."""
    base, main, sub = (int_param(p) & 0xFF for p in params[:3])
    if not base & px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        return None
    wanted = (main, sub if main == px4.MainMode.AUTO else 0)
    return next((name for name, pair in px4.MODES.items() if (int(pair[0]), int(pair[1])) == wanted), None)


def setpoint_of(msg: Any, yaw_rad: float) -> tuple[Setpoint | None, str]:
    """SET_POSITION_TARGET_LOCAL_NED as PX4's ``mavlink_receiver`` reads it: (the setpoint in
    local NED, "") or (None, the STATUSTEXT PX4 logs when it drops the message).

    LOCAL_NED (1): each field is NaN when its ignore bit is set, else taken as sent (NaN or inf
    included: PX4's position controller then holds, see :mod:`sim.vehicle.physics.mc_position_control`).
    BODY_NED (8): velocity (unless any of its bits is ignored) and acceleration rotated by the
    yaw ``yaw_rad`` (*PX4 rotates the acceleration by the full attitude), never a position.
    Any other frame, an acceleration with the FORCE bit (512), or nothing at all to control is
    dropped (and is not proof of life).
    """
    frame, mask = msg.coordinate_frame, int(msg.type_mask)

    def field(bit: int, value: float) -> float:
        return NAN if mask & bit else float(value)

    if frame == px4.MAV_FRAME_LOCAL_NED:
        position = (field(X_IGNORE, msg.x), field(Y_IGNORE, msg.y), field(Z_IGNORE, msg.z))
        velocity = (field(VX_IGNORE, msg.vx), field(VY_IGNORE, msg.vy), field(VZ_IGNORE, msg.vz))
        acceleration = (field(AX_IGNORE, msg.afx), field(AY_IGNORE, msg.afy), field(AZ_IGNORE, msg.afz))
    elif frame == px4.MAV_FRAME_BODY_NED:
        position = (NAN, NAN, NAN)
        velocity = (NAN, NAN, NAN) if mask & (VX_IGNORE | VY_IGNORE | VZ_IGNORE) else body_to_ned(msg.vx, msg.vy, msg.vz, yaw_rad)
        acceleration = (NAN, NAN, NAN) if mask & (AX_IGNORE | AY_IGNORE | AZ_IGNORE) \
            else body_to_ned(float(msg.afx), float(msg.afy), float(msg.afz), yaw_rad)
    else:
        return None, f"SET_POSITION_TARGET_LOCAL_NED coordinate frame {frame} unsupported"
    has_acceleration = not all(math.isnan(a) for a in acceleration)
    if has_acceleration and mask & FORCE_SET:
        return None, "SET_POSITION_TARGET_LOCAL_NED force not supported"
    if all(math.isnan(x) for x in (*position, *velocity)) and not has_acceleration:
        return None, "SET_POSITION_TARGET_LOCAL_NED invalid"
    yaw = None if mask & YAW_IGNORE or not math.isfinite(msg.yaw) else float(msg.yaw)
    yaw_rate = None if mask & YAW_RATE_IGNORE or not math.isfinite(msg.yaw_rate) else float(msg.yaw_rate)
    return Setpoint(position, velocity, acceleration, yaw, yaw_rate, mask), ""


def param_value(params: ParamTable, name: str) -> Any:
    """PARAM_VALUE of ``name`` (integers bit-packed in the float, as PX4 sends them)."""
    value, kind = params.wire(name)
    return mavlink.MAVLink_param_value_message(name.encode(), value, kind, len(params), params.index_of(name))
