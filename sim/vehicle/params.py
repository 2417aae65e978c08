"""PX4 parameter table of the mock vehicle and the MAVLink parameter encoding.

Only the parameters the mock vehicle actually uses are present; the values are PX4's defaults
as seen on a real SITL (../shared/REFERENCE.md). Integer parameters travel bit-packed in the
float field of PARAM_VALUE / PARAM_SET ("bytewise" encoding, as PX4 does): the int32 bits are
reinterpreted as a float32, never converted.
"""
from __future__ import annotations

import math
import threading
from dataclasses import dataclass

from mission.mavlink import px4
from mission.mavlink.px4 import pack_int32, unpack_int32
from sim.vehicle.physics.mc_position_control import Gains
from sim.vehicle.physics.multicopter import Limits


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: name (<= 16 chars), PX4 default, and whether it is an int32."""

    name: str
    default: float
    is_int: bool
    doc: str


PARAM_SPECS: tuple[ParamSpec, ...] = (
    ParamSpec("COM_OF_LOSS_T", 1.0, False, "offboard loss timeout [s]"),
    ParamSpec("COM_OBL_RC_ACT", 0, True, "offboard loss action: 0 Position 1 Altitude 2 Stabilized 3 Return 4 Land 5 Hold 6 Terminate 7 Disarm"),
    ParamSpec("COM_DISARM_PRFLT", 10.0, False, "auto-disarm when armed but not taken off [s]; <= 0 disables"),
    ParamSpec("COM_DISARM_LAND", 2.0, False, "auto-disarm after landing [s]; <= 0 disables"),
    ParamSpec("COM_DL_LOSS_T", 10, True, "data link loss timeout [s] (reported only)"),
    ParamSpec("LNDMC_TRIG_TIME", 1.0, False, "land detector trigger time [s]; a disarmed vehicle reports landed after a third of it"),
    ParamSpec("COM_RC_IN_MODE", 1, True, "RC input mode (reported only; the mock has no RC)"),
    ParamSpec("COM_ARM_WO_GPS", 1, True, "allow arming without GPS (reported only)"),
    ParamSpec("NAV_RCL_ACT", 2, True, "RC loss action (reported only)"),
    ParamSpec("MPC_XY_VEL_MAX", 12.0, False, "horizontal speed limit [m/s]"),
    ParamSpec("MPC_XY_CRUISE", 5.0, False, "horizontal speed of auto modes (RTL) [m/s]"),
    ParamSpec("MPC_Z_VEL_MAX_UP", 3.0, False, "climb speed limit [m/s]"),
    ParamSpec("MPC_Z_VEL_MAX_DN", 1.5, False, "descent speed limit [m/s]"),
    ParamSpec("MPC_ACC_HOR", 3.0, False, "horizontal acceleration of auto modes [m/s^2] (reported only: OFFBOARD is not smoothed)"),
    ParamSpec("MPC_ACC_HOR_MAX", 5.0, False, "horizontal acceleration limit of manual modes [m/s^2] (reported only)"),
    ParamSpec("MPC_ACC_UP_MAX", 4.0, False, "upward acceleration of auto modes [m/s^2] (reported only)"),
    ParamSpec("MPC_ACC_DOWN_MAX", 3.0, False, "downward acceleration of auto modes [m/s^2] (reported only)"),
    ParamSpec("MPC_JERK_MAX", 8.0, False, "jerk limit of manual modes [m/s^3] (reported only)"),
    ParamSpec("MPC_JERK_AUTO", 4.0, False, "jerk limit of auto modes [m/s^3] (reported only)"),
    ParamSpec("MPC_XY_P", 0.95, False, "horizontal position gain [1/s]"),
    ParamSpec("MPC_Z_P", 1.0, False, "vertical position gain [1/s]"),
    ParamSpec("MPC_XY_VEL_P_ACC", 1.8, False, "horizontal velocity P gain [1/s]"),
    ParamSpec("MPC_XY_VEL_I_ACC", 0.4, False, "horizontal velocity I gain [1/s^2]"),
    ParamSpec("MPC_XY_VEL_D_ACC", 0.2, False, "horizontal velocity D gain [-]"),
    ParamSpec("MPC_Z_VEL_P_ACC", 4.0, False, "vertical velocity P gain [1/s]"),
    ParamSpec("MPC_Z_VEL_I_ACC", 2.0, False, "vertical velocity I gain [1/s^2]"),
    ParamSpec("MPC_Z_VEL_D_ACC", 0.0, False, "vertical velocity D gain [-]"),
    ParamSpec("MPC_VELD_LP", 5.0, False, "low-pass cutoff of the velocity derivative (D term) [Hz]"),
    ParamSpec("MPC_TILTMAX_AIR", 45.0, False, "tilt limit in the air [deg]"),
    ParamSpec("MPC_THR_HOVER", 0.5, False, "hover thrust [0..1]"),
    ParamSpec("MPC_THR_MIN", 0.12, False, "minimum collective thrust [0..1]"),
    ParamSpec("MPC_THR_MAX", 1.0, False, "maximum collective thrust [0..1]"),
    ParamSpec("MPC_THR_XY_MARG", 0.3, False, "horizontal thrust margin [0..1]"),
    ParamSpec("MPC_TKO_SPEED", 1.5, False, "takeoff climb speed [m/s]"),
    ParamSpec("MPC_LAND_SPEED", 0.7, False, "landing descent speed [m/s]"),
    ParamSpec("MPC_YAWRAUTO_MAX", 45.0, False, "yaw rate limit [deg/s]"),
    ParamSpec("MIS_TAKEOFF_ALT", 2.5, False, "default takeoff altitude above home [m]"),
    ParamSpec("RTL_PLD_MD", 0, True, "RTL's precision landing: 0 off 1 opportunistic 2 required (kept, not flown)"),
    ParamSpec("RTL_RETURN_ALT", 30.0, False, "RTL return altitude above the destination [m] (multicopter default)"),
    ParamSpec("RTL_MIN_DIST", 10.0, False, "within this horizontal distance [m] of the destination RTL returns in the cone"),
    ParamSpec("RTL_CONE_ANG", 45, True, "half angle [deg] of RTL's altitude cone round the destination (0: none)"),
    ParamSpec("NAV_ACC_RAD", 2.0, False, "acceptance radius [m] (multicopter default): RTL's lowest return is twice it"),
    ParamSpec("LNDMC_XY_VEL_MAX", 1.5, False, "land detector: no ground contact while moving faster horizontally [m/s]"),
    ParamSpec("COM_HOME_EN", 1, True, "home position enabled: DO_SET_HOME is refused (DENIED) when 0"),
    ParamSpec("SIM_BAT_ENABLE", 0, True, "simulate the battery (*PX4 SITL: 1; the mock: 0 unless asked)"),
    ParamSpec("SIM_BAT_DRAIN", 60.0, False, "battery simulator: time to drain a full battery while armed [s]"),
    ParamSpec("SIM_BAT_MIN_PCT", 50.0, False, "battery simulator: the charge never falls below this [%]"),
    ParamSpec("BAT1_N_CELLS", 4, True, "cells of battery 1 (PX4 SITL: 4)"),
    ParamSpec("BAT1_V_CHARGED", 4.05, False, "full cell voltage [V]"),
    ParamSpec("BAT1_V_EMPTY", 3.6, False, "empty cell voltage [V]"),
    ParamSpec("BAT_LOW_THR", 0.15, False, "low battery threshold [fraction]: a warning"),
    ParamSpec("BAT_CRIT_THR", 0.07, False, "critical battery threshold [fraction]: COM_LOW_BAT_ACT acts"),
    ParamSpec("BAT_EMERGEN_THR", 0.05, False, "emergency battery threshold [fraction]: COM_LOW_BAT_ACT acts"),
    ParamSpec("COM_LOW_BAT_ACT", 3, True, "low battery action: 0 warning, 2 Land, 3 Return at critical and Land at emergency "
                                          "(PX4 SITL's rcS sets 3)"),
    ParamSpec("MAV_SYS_ID", 1, True, "MAVLink system id (reported only)"),
)
SPECS_BY_NAME = {spec.name: spec for spec in PARAM_SPECS}


class UnknownParam(KeyError):
    """No parameter of that name or index."""


class ParamTable:
    """Thread-safe parameter values with PX4 wire encoding. Values are ``float`` or ``int``."""

    def __init__(self, overrides: dict[str, float] | None = None, sysid: int = 1) -> None:
        self._lock = threading.Lock()
        self._values: dict[str, float | int] = {s.name: (int(s.default) if s.is_int else float(s.default)) for s in PARAM_SPECS}
        self._values["MAV_SYS_ID"] = int(sysid)
        self.version = 0  # incremented by every change (lets readers cache what they derive)
        for name, value in (overrides or {}).items():
            self.set(name, value)

    def __len__(self) -> int:
        return len(PARAM_SPECS)

    def get(self, name: str) -> float:
        """Current value of ``name`` (as float, also for int parameters)."""
        with self._lock:
            return float(self._values[name])

    def set(self, name: str, value: float) -> float | int:
        """Set ``name`` to ``value`` (rounded for int parameters); return the stored value."""
        spec = SPECS_BY_NAME.get(name)
        if spec is None:
            raise UnknownParam(name)
        if not math.isfinite(float(value)):
            raise ValueError(f"{name}: value must be finite, got {value!r}")
        stored: float | int = int(round(value)) if spec.is_int else float(value)
        with self._lock:
            self._values[name] = stored
            self.version += 1
        return stored

    def set_from_wire(self, name: str, wire_value: float, wire_type: int) -> float | int:
        """Apply a PARAM_SET: ints arrive bit-packed when ``wire_type`` is an integer type."""
        value = float(unpack_int32(wire_value)) if wire_type != px4.MAV_PARAM_TYPE_REAL32 else wire_value
        return self.set(name, value)

    def index_of(self, name: str) -> int:
        for index, spec in enumerate(PARAM_SPECS):
            if spec.name == name:
                return index
        raise UnknownParam(name)

    def name_at(self, index: int) -> str:
        if not 0 <= index < len(PARAM_SPECS):
            raise UnknownParam(index)
        return PARAM_SPECS[index].name

    def wire(self, name: str) -> tuple[float, int]:
        """(float field, MAV_PARAM_TYPE) of ``name`` as PARAM_VALUE carries it."""
        spec = SPECS_BY_NAME[name]
        with self._lock:
            value = self._values[name]
        if spec.is_int:
            return pack_int32(int(value)), px4.MAV_PARAM_TYPE_INT32
        return float(value), px4.MAV_PARAM_TYPE_REAL32


def vehicle_limits(table: ParamTable) -> Limits:
    """The dynamics' gains and limits from the current parameter values (airframe: the fitted one)."""
    p = table.get
    gains = Gains(p("MPC_XY_P"), p("MPC_Z_P"), p("MPC_XY_VEL_P_ACC"), p("MPC_XY_VEL_I_ACC"), p("MPC_XY_VEL_D_ACC"),
                  p("MPC_Z_VEL_P_ACC"), p("MPC_Z_VEL_I_ACC"), p("MPC_Z_VEL_D_ACC"), p("MPC_VELD_LP"), p("MPC_XY_VEL_MAX"),
                  p("MPC_Z_VEL_MAX_UP"), p("MPC_Z_VEL_MAX_DN"), math.radians(p("MPC_TILTMAX_AIR")), p("MPC_THR_HOVER"),
                  p("MPC_THR_MIN"), p("MPC_THR_MAX"), p("MPC_THR_XY_MARG"))
    return Limits(gains, yaw_rate_max_rad_s=math.radians(p("MPC_YAWRAUTO_MAX")))

