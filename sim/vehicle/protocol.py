"""Pure MAVLink decoding rules of the mock vehicle: what PX4 makes of a command or a setpoint.

No I/O and no state: message fields in, a decision out (a mode name, a
:class:`~sim.vehicle.modes.TrajectorySetpoint` in local NED, or None when PX4 would drop the message).
"""
from __future__ import annotations

import math
from typing import Any

from mission.mavlink import px4, setpoints
from mission.mavlink.env import mavlink
from mission.mavlink.setpoints import decode_target
from sim.vehicle.modes import NAN3, TrajectorySetpoint
from sim.vehicle.params import ParamTable
from sim.vehicle.physics.multicopter import body_to_ned


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


def setpoint_of(msg: Any, yaw_rad: float) -> tuple[TrajectorySetpoint | None, str]:
    """SET_POSITION_TARGET_LOCAL_NED as PX4's ``mavlink_receiver`` reads it: (the setpoint in
    local NED, "") or (None, the STATUSTEXT PX4 logs when it drops the message).

    The fields are decoded by :func:`mission.mavlink.setpoints.decode_target`, the module that
    encodes the controller's setpoints. LOCAL_NED (1): each field is NaN when its ignore bit is
    set, else taken as sent (NaN or inf included: PX4's position controller then holds, see
    :mod:`sim.vehicle.physics.mc_position_control`). BODY_NED (8): velocity (unless any of its
    bits is ignored) and acceleration rotated by the yaw ``yaw_rad`` (*PX4 rotates the
    acceleration by the full attitude), never a position. Any other frame, an acceleration with
    the FORCE bit (512), or nothing at all to control is dropped (and is not proof of life).
    """
    t = decode_target(msg)
    if t.frame == px4.MAV_FRAME_LOCAL_NED:
        position, velocity, acceleration = t.position, t.velocity, t.acceleration
    elif t.frame == px4.MAV_FRAME_BODY_NED:
        position = NAN3
        velocity = NAN3 if t.type_mask & setpoints.VELOCITY_IGNORE else body_to_ned(*t.velocity, yaw_rad)
        acceleration = NAN3 if t.type_mask & setpoints.ACCELERATION_IGNORE else body_to_ned(*t.acceleration, yaw_rad)
    else:
        return None, f"SET_POSITION_TARGET_LOCAL_NED coordinate frame {t.frame} unsupported"
    has_acceleration = not all(math.isnan(a) for a in acceleration)
    if has_acceleration and t.force:
        return None, "SET_POSITION_TARGET_LOCAL_NED force not supported"
    if all(math.isnan(x) for x in (*position, *velocity)) and not has_acceleration:
        return None, "SET_POSITION_TARGET_LOCAL_NED invalid"
    return TrajectorySetpoint(position, velocity, acceleration, t.yaw_rad, t.yaw_rate_rad_s, t.type_mask), ""


def param_value(params: ParamTable, name: str) -> Any:
    """PARAM_VALUE of ``name`` (integers bit-packed in the float, as PX4 sends them)."""
    value, kind = params.wire(name)
    return mavlink.MAVLink_param_value_message(name.encode(), value, kind, len(params), params.index_of(name))
