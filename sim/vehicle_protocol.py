"""Pure MAVLink decoding rules of the mock vehicle: what PX4 makes of a command or a setpoint.

No I/O and no state: message fields in, a decision out (a mode name, a :class:`Setpoint` in
local NED, or None when PX4 would drop the message).
"""
from __future__ import annotations

import math
from typing import Any

from mission import px4
from mission.mavlink_env import mavlink
from sim.vehicle_commander import Setpoint
from sim.vehicle_params import ParamTable
from sim.vehicle_physics import body_to_ned

# type_mask -> what the setpoint carries; any other mask is dropped (and is not proof of life)
SETPOINT_KINDS = {
    px4.TYPE_MASK_VELOCITY: "velocity",
    px4.TYPE_MASK_VELOCITY_YAW: "velocity",
    px4.TYPE_MASK_VELOCITY_YAW_RATE: "velocity",
    px4.TYPE_MASK_POSITION: "position",
}


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


def setpoint_of(msg: Any, yaw_rad: float) -> Setpoint | None:
    """SET_POSITION_TARGET_LOCAL_NED as a setpoint in local NED, or None if PX4 would drop it.

    Frames LOCAL_NED (1) and BODY_NED (8, velocity rotated by the current ``yaw_rad`` only);
    masks velocity (3527), velocity + yaw (2503), velocity + yaw rate (1479) and position + yaw
    (2552, LOCAL_NED only). The fields a mask uses must be finite.
    """
    frame, mask = msg.coordinate_frame, msg.type_mask
    kind = SETPOINT_KINDS.get(mask)
    if kind is None or frame not in (px4.MAV_FRAME_LOCAL_NED, px4.MAV_FRAME_BODY_NED):
        return None
    if kind == "position":
        ned = (msg.x, msg.y, msg.z)
        if frame != px4.MAV_FRAME_LOCAL_NED or not all(map(math.isfinite, ned)):
            return None
        return Setpoint("position", ned, msg.yaw if math.isfinite(msg.yaw) else None, None, mask)
    velocity = (msg.vx, msg.vy, msg.vz)
    if not all(map(math.isfinite, velocity)):
        return None
    if frame == px4.MAV_FRAME_BODY_NED:
        velocity = body_to_ned(*velocity, yaw_rad)
    yaw = msg.yaw if mask == px4.TYPE_MASK_VELOCITY_YAW and math.isfinite(msg.yaw) else None
    yaw_rate = msg.yaw_rate if mask == px4.TYPE_MASK_VELOCITY_YAW_RATE and math.isfinite(msg.yaw_rate) else None
    return Setpoint("velocity", velocity, yaw, yaw_rate, mask)


def param_value(params: ParamTable, name: str) -> Any:
    """PARAM_VALUE of ``name`` (integers bit-packed in the float, as PX4 sends them)."""
    value, kind = params.wire(name)
    return mavlink.MAVLink_param_value_message(name.encode(), value, kind, len(params), params.index_of(name))
