"""Mode logic of the mock vehicle: arming, modes, failsafes, and the per-mode velocity command.

A small PX4-like commander with no I/O. The vehicle feeds it commands and setpoints (already
validated and converted to local NED), calls :meth:`Commander.step` once per physics step, and
sends the STATUSTEXTs it leaves in :attr:`Commander.outbox`. Times are simulated seconds [s].

State machine (PX4 behaviour from ../shared/REFERENCE.md; choices of this mock marked *):
- Start: disarmed in Hold (AUTO.LOITER).
- DO_SET_MODE OFFBOARD: accepted only if a valid setpoint arrived within COM_OF_LOSS_T and the
  position estimate is valid, else TEMPORARILY_REJECTED. *Also when disarmed (the real PX4
  accepts OFFBOARD while disarmed with no stream and then refuses to arm; we refuse the switch).
- An injected OFFBOARD refusal (fault) rejects DO_SET_MODE OFFBOARD with its STATUSTEXT.
- DO_SET_MODE to a manual mode (POSCTL, ALTCTL, ...): *TEMPORARILY_REJECTED unless a pilot is
  present (:meth:`force_mode` = a pilot took over): the mock has no RC.
- Arming: denied (TEMPORARILY_REJECTED + STATUSTEXT) when an arming refusal is injected, the
  position estimate is invalid, in OFFBOARD without a fresh setpoint, or in a manual mode with no
  pilot. Force (param2 = 21196) does not skip them for a MAVLink command: PX4's Commander skips
  them only for a forced arm of its own (``commander arm -f``; docs/flying-px4.md). Disarming in
  the air needs force.
- Offboard loss (armed, OFFBOARD, no setpoint for COM_OF_LOSS_T): "Failsafe activated", mode of
  COM_OBL_RC_ACT (6 Terminate and 7 Disarm disarm), in_failsafe. When setpoints resume while that
  failsafe is active and nobody changed the mode, back to OFFBOARD at the next step (PX4 does so
  within ~0.2 s).
- Manual mode without pilot (the offboard-loss failsafe): hold the horizontal position, descend
  at MPC_LAND_SPEED, land, disarm after COM_DISARM_LAND (as PX4 SITL does).
- Position estimate lost while armed in a mode that needs it: failsafe to AUTO.LAND (PX4's
  Descend reports as AUTO.LAND): no horizontal hold, descend at MPC_LAND_SPEED.
- Auto-disarm: COM_DISARM_PRFLT after arming if not taken off; COM_DISARM_LAND after landing.
- Disarming clears the failsafe; the mode stays (a new arm needs an armable mode). Disarmed in
  the air (only by force) the motors stop and it falls.
- Landed state: on the ground, or disarmed for LNDMC_TRIG_TIME / 3 (PX4's land detector counts a
  disarmed vehicle as landed, through a hysteresis of that length): ON_GROUND even while a
  force-disarmed vehicle is still falling.
- Home: set where the vehicle arms on the ground, unless DO_SET_HOME set it (PX4's
  ``manual_home``: it then stays until the next DO_SET_HOME). DO_SET_HOME (COMMAND_LONG or
  COMMAND_INT; param1 = 1: here, else lat/lon/alt) is accepted armed or not, in flight too, with
  a valid position estimate (else TEMPORARILY_REJECTED); non-finite coordinates: DENIED; COM_HOME_EN
  = 0: DENIED. No rate limit (a PX4 SITL took 5 a second, each ACCEPTED).
- RTL fixes its destination (the home) and its return altitude when it starts: a home moved
  during the return is not followed (as on PX4 SITL, whose RTL also takes them at activation).
  Return altitude as PX4's ``computeReturnAltitude`` for a multicopter: RTL_RETURN_ALT above the
  home; within RTL_MIN_DIST, the RTL_CONE_ANG cone's height at that distance; at least 2 x
  NAV_ACC_RAD; never lower than the vehicle is. *No descent to RTL_DESCEND_ALT and loiter: it
  descends at MPC_LAND_SPEED all the way.
- Battery (SIM_BAT_ENABLE, :mod:`sim.vehicle.physics.battery`): below BAT_LOW_THR a warning; below
  BAT_CRIT_THR, COM_LOW_BAT_ACT 3: failsafe Return, 2: failsafe Land; below BAT_EMERGEN_THR, 2 or
  3: failsafe Land. *Each once, on the way down; PX4's failsafe framework adds a hold delay and
  user takeover.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from mission.mavlink import px4, setpoints
from sim.vehicle.physics import battery
from sim.vehicle.params import ParamTable
from sim.vehicle.physics.multicopter import Command, KinState

POSITION_GAIN_1_S = 1.0  # P gain of the position loops (Hold, position setpoints) [1/s]
ARRIVAL_RADIUS_M = 0.5
TAKEOFF_DONE_M = 0.1
REJECTION_REPEAT_S = 1.0  # [s] a dropped setpoint's STATUSTEXT is repeated at most this often

MODES_NEEDING_POSITION = frozenset({"OFFBOARD", "POSCTL", "AUTO.LOITER", "AUTO.TAKEOFF", "AUTO.RTL", "AUTO.MISSION", "AUTO.READY"})


NAN3 = (math.nan, math.nan, math.nan)


@dataclass(frozen=True)
class TrajectorySetpoint:
    """An accepted offboard setpoint in local NED, as PX4's trajectory setpoint: position [m],
    velocity [m/s], acceleration [m/s^2]; NaN components are not controlled. An absolute yaw
    [rad] or a yaw rate [rad/s] (both None: keep the yaw)."""

    position: tuple[float, float, float] = NAN3
    velocity: tuple[float, float, float] = NAN3
    acceleration: tuple[float, float, float] = NAN3
    yaw_rad: float | None = None
    yaw_rate_rad_s: float | None = None
    type_mask: int = setpoints.TYPE_MASK_VELOCITY


class Commander:
    """PX4-like mode and arming logic; see the module docstring for the transitions."""

    def __init__(self, params: ParamTable, kin: KinState) -> None:
        self.params = params
        self.mode = px4.HOLD
        self.user_mode = px4.HOLD
        self.armed = False
        self.in_failsafe = False
        self.failsafe_reason: str | None = None
        self.failsafe_t_s = -math.inf
        self.pilot_present = False
        self.position_valid = True
        self.refuse_arming_reason: str | None = None
        self.refuse_offboard_reason: str | None = None
        self.setpoint: TrajectorySetpoint | None = None
        self.last_setpoint_t_s = -math.inf
        self.setpoints_received = 0
        self.setpoints_at_failsafe = 0
        self.arm_t_s = -math.inf
        self.disarm_t_s = -math.inf
        self.taken_off = False
        self.landed_t_s: float | None = None
        self.hold_ned_m = (kin.n_m, kin.e_m, kin.d_m)
        self.home_ned_m = (kin.n_m, kin.e_m, kin.d_m)
        self.manual_home = False  # DO_SET_HOME set it: arming no longer moves it
        self.takeoff_d_m = kin.d_m
        self.rtl_phase = "climb"
        self.rtl_return_d_m = kin.d_m
        self.rtl_home_ned_m = self.home_ned_m  # RTL's destination, fixed when it starts
        self.battery = battery.Battery(params)
        self.now_s = 0.0  # time of the latest step or command [s]
        self.outbox: list[tuple[float, int, str]] = []  # (t_s, severity, text) to send
        self._rejections: dict[str, float] = {}  # STATUSTEXT of a dropped setpoint -> when last said
        self.kin = kin

    # ---- helpers -------------------------------------------------------------------------
    def _say(self, text: str, severity: int = px4.MAV_SEVERITY_INFO) -> None:
        self.outbox.append((self.now_s, severity, text))

    def _enter(self, name: str, by_user: bool = True) -> None:
        """Switch to mode ``name``; its position targets start from where the vehicle is."""
        kin = self.kin
        self.mode = name
        if by_user:
            self.user_mode = name
        self.hold_ned_m = (kin.n_m, kin.e_m, kin.d_m)
        self.rtl_phase = "climb"
        self.rtl_home_ned_m = self.home_ned_m
        self.rtl_return_d_m = rtl_return_d_m(self.params, self.rtl_home_ned_m, kin)
        if name == "AUTO.TAKEOFF":
            self.takeoff_d_m = self.home_ned_m[2] - self.params.get("MIS_TAKEOFF_ALT")

    def setpoint_fresh(self, t_s: float) -> bool:
        """A valid setpoint arrived within COM_OF_LOSS_T."""
        return t_s - self.last_setpoint_t_s <= self.params.get("COM_OF_LOSS_T")

    def _needs_pilot(self, name: str) -> bool:
        return name in px4.MANUAL_MODES and not self.pilot_present

    # ---- inputs --------------------------------------------------------------------------
    def accept_setpoint(self, t_s: float, setpoint: TrajectorySetpoint) -> None:
        """A valid setpoint arrived (proof of life in any mode; acted on in OFFBOARD)."""
        self.setpoint = setpoint
        self.last_setpoint_t_s = t_s
        self.setpoints_received += 1

    def reject_setpoint(self, t_s: float, reason: str) -> None:
        """A setpoint was dropped: PX4 logs ``reason`` as a critical STATUSTEXT (*here at most
        once per :data:`REJECTION_REPEAT_S` per text, where PX4 repeats it for every message)."""
        self.now_s = max(self.now_s, t_s)
        if t_s - self._rejections.get(reason, -math.inf) >= REJECTION_REPEAT_S:
            self._rejections[reason] = t_s
            self._say(reason, px4.MAV_SEVERITY_CRITICAL)

    def set_mode(self, t_s: float, name: str) -> int:
        """Handle DO_SET_MODE to mode ``name``; return the MAV_RESULT."""
        self.now_s = max(self.now_s, t_s)
        if name == self.mode:
            self.user_mode = name
            return px4.MAV_RESULT_ACCEPTED
        if name == "OFFBOARD" and self.refuse_offboard_reason:
            self._say(self.refuse_offboard_reason, px4.MAV_SEVERITY_CRITICAL)
            return px4.MAV_RESULT_TEMPORARILY_REJECTED
        refusal = self._mode_refusal(t_s, name)
        if refusal:
            self._say(f"Mode {name} rejected: {refusal}", px4.MAV_SEVERITY_CRITICAL)
            return px4.MAV_RESULT_TEMPORARILY_REJECTED
        self.in_failsafe, self.failsafe_reason = False, None
        self._enter(name)
        return px4.MAV_RESULT_ACCEPTED

    def _mode_refusal(self, t_s: float, name: str) -> str:
        if name in MODES_NEEDING_POSITION and not self.position_valid:
            return "no local position estimate"
        if name == "OFFBOARD" and not self.setpoint_fresh(t_s):
            return "no offboard signal"
        if self._needs_pilot(name):
            return "no manual control (RC)"
        return ""

    def arm(self, t_s: float, force: bool = False) -> int:
        """Handle an arm request; return the MAV_RESULT. ``force`` skips the checks (PX4's own
        forced arm; a MAVLink command never does)."""
        self.now_s = max(self.now_s, t_s)
        if self.armed:
            return px4.MAV_RESULT_ACCEPTED
        reason = "" if force else self._arming_refusal(t_s)
        if reason:
            self._say(reason, px4.MAV_SEVERITY_CRITICAL)
            return px4.MAV_RESULT_TEMPORARILY_REJECTED
        kin = self.kin
        self.armed, self.arm_t_s, self.taken_off, self.landed_t_s = True, t_s, False, None
        if kin.on_ground and not self.manual_home:
            self.home_ned_m = (kin.n_m, kin.e_m, kin.d_m)
        self.hold_ned_m = (kin.n_m, kin.e_m, kin.d_m)
        self._say("Armed by external command")
        return px4.MAV_RESULT_ACCEPTED

    def _arming_refusal(self, t_s: float) -> str:
        if self.refuse_arming_reason:
            return self.refuse_arming_reason
        if not self.position_valid:
            return "Arming denied: Resolve system health failures first (no local position)"
        if self.mode == "OFFBOARD" and not self.setpoint_fresh(t_s):
            return "Arming denied: Resolve system health failures first"
        if self._needs_pilot(self.mode):
            return "Arming denied: manual control lost"
        return ""

    def disarm(self, t_s: float, force: bool = False, reason: str = "Disarmed by external command") -> int:
        """Handle a disarm request; in the air only with ``force``. Return the MAV_RESULT."""
        self.now_s = max(self.now_s, t_s)
        if not self.armed:
            return px4.MAV_RESULT_ACCEPTED
        if not force and not self.kin.on_ground:
            self._say("Disarming denied: not landed", px4.MAV_SEVERITY_CRITICAL)
            return px4.MAV_RESULT_TEMPORARILY_REJECTED
        self.armed, self.disarm_t_s = False, t_s
        self.in_failsafe, self.failsafe_reason = False, None
        self._say(reason)
        return px4.MAV_RESULT_ACCEPTED

    def takeoff(self, t_s: float, altitude_above_home_m: float | None) -> int:
        """NAV_TAKEOFF: climb to ``altitude_above_home_m`` (None: MIS_TAKEOFF_ALT), then Hold."""
        self.now_s = max(self.now_s, t_s)
        if not self.position_valid:
            return px4.MAV_RESULT_TEMPORARILY_REJECTED
        alt_m = self.params.get("MIS_TAKEOFF_ALT") if altitude_above_home_m is None else altitude_above_home_m
        self.in_failsafe, self.failsafe_reason = False, None
        self._enter("AUTO.TAKEOFF")
        self.takeoff_d_m = self.home_ned_m[2] - alt_m
        return px4.MAV_RESULT_ACCEPTED

    def set_home(self, t_s: float, home_ned_m: tuple[float, float, float] | None) -> int:
        """DO_SET_HOME: the home at ``home_ned_m`` [m] NED (None: where the vehicle is); return the
        MAV_RESULT (see the module docstring)."""
        self.now_s = max(self.now_s, t_s)
        if not self.params.get("COM_HOME_EN"):
            return px4.MAV_RESULT_DENIED
        if home_ned_m is not None and not all(math.isfinite(c) for c in home_ned_m):
            return px4.MAV_RESULT_DENIED
        if not self.position_valid:
            return px4.MAV_RESULT_TEMPORARILY_REJECTED
        kin = self.kin
        self.home_ned_m = (kin.n_m, kin.e_m, kin.d_m) if home_ned_m is None else tuple(home_ned_m)  # type: ignore[assignment]
        self.manual_home = True
        return px4.MAV_RESULT_ACCEPTED

    def force_mode(self, t_s: float, name: str) -> None:
        """A pilot takes over and switches to ``name`` (no checks; clears a failsafe)."""
        self.now_s = max(self.now_s, t_s)
        if name not in px4.MODES:
            raise ValueError(f"unknown mode {name!r}; known: {sorted(px4.MODES)}")
        self.pilot_present = True
        self.in_failsafe, self.failsafe_reason = False, None
        self._enter(name)

    # ---- per step ------------------------------------------------------------------------
    def step(self, t_s: float, kin: KinState) -> Command:
        """Apply the timers and failsafes at time ``t_s`` and return the command for ``kin``."""
        self.now_s = max(self.now_s, t_s)
        self.kin = kin
        self._battery_failsafe(t_s, self.battery.update(t_s, self.armed))
        if self.armed:
            self._track_landing(t_s, kin)
            self._auto_disarm(t_s, kin)
        if self.armed:
            self._failsafes(t_s)
        if not self.armed:
            return Command(powered=False)
        return self._mode_command(kin)

    def _track_landing(self, t_s: float, kin: KinState) -> None:
        if not kin.on_ground:
            if not self.taken_off:
                self._say("Takeoff detected")
            self.taken_off, self.landed_t_s = True, None
        elif self.taken_off and self.landed_t_s is None:
            self.landed_t_s = t_s
            self._say("Landing detected")

    def _auto_disarm(self, t_s: float, kin: KinState) -> None:
        if not kin.on_ground:
            return
        prflt_s, land_s = self.params.get("COM_DISARM_PRFLT"), self.params.get("COM_DISARM_LAND")
        if not self.taken_off and prflt_s > 0 and t_s - self.arm_t_s >= prflt_s:
            self.disarm(t_s, reason="Disarmed by auto preflight disarming")
        elif self.landed_t_s is not None and land_s > 0 and t_s - self.landed_t_s >= land_s:
            self.disarm(t_s, reason="Disarmed by landing")

    def _failsafes(self, t_s: float) -> None:
        if not self.position_valid and self.mode in MODES_NEEDING_POSITION:
            self._activate_failsafe(t_s, "AUTO.LAND", "no local position")
        elif self.mode == "OFFBOARD" and not self.setpoint_fresh(t_s):
            self._offboard_lost(t_s)
        elif (self.in_failsafe and self.failsafe_reason == "offboard loss" and self.user_mode == "OFFBOARD"
              and self.setpoints_received > self.setpoints_at_failsafe and self.position_valid):
            self.in_failsafe, self.failsafe_reason = False, None
            self._enter("OFFBOARD", by_user=False)
            self._say("Failsafe deactivated: offboard signal regained")

    def _battery_failsafe(self, t_s: float, level: battery.BatteryWarning | None) -> None:
        """PX4's reaction to a battery level newly reached in the air (COM_LOW_BAT_ACT)."""
        if level is None:
            return
        action = int(self.params.get("COM_LOW_BAT_ACT"))
        if level == battery.BatteryWarning.LOW or action not in (2, 3):
            self._say(f"Low battery level! ({self.battery.reading()[0]} %)", px4.MAV_SEVERITY_WARNING)  # type: ignore[index]
        elif level == battery.BatteryWarning.CRITICAL:
            self._activate_failsafe(t_s, "AUTO.RTL" if action == 3 else "AUTO.LAND", "battery critical")
        else:
            self._activate_failsafe(t_s, "AUTO.LAND", "battery emergency")

    def _offboard_lost(self, t_s: float) -> None:
        action = int(self.params.get("COM_OBL_RC_ACT"))
        if action in (6, 7):
            self._say("Failsafe activated: offboard loss, disarming", px4.MAV_SEVERITY_CRITICAL)
            self.disarm(t_s, force=True, reason="Disarmed by failsafe")
            return
        self._activate_failsafe(t_s, px4.OFFBOARD_LOSS_ACTION_MODE.get(action, "POSCTL"), "offboard loss")

    def _activate_failsafe(self, t_s: float, mode: str, reason: str) -> None:
        self.in_failsafe, self.failsafe_reason, self.failsafe_t_s = True, reason, t_s
        self.setpoints_at_failsafe = self.setpoints_received
        self._enter(mode, by_user=False)
        self._say(f"Failsafe activated: {reason}", px4.MAV_SEVERITY_CRITICAL)

    # ---- per-mode command ----------------------------------------------------------------
    def _mode_command(self, kin: KinState) -> Command:
        mode = self.mode
        if mode == "OFFBOARD" and self.setpoint is not None:
            return offboard_command(kin, self.setpoint)
        if mode == "AUTO.LAND" or self._needs_pilot(mode):
            return self.descend_command(kin)
        if mode == "AUTO.TAKEOFF":
            return self._takeoff_command(kin)
        if mode == "AUTO.RTL":
            return rtl_command(self, kin)
        return hold_command(kin, self.hold_ned_m)

    def descend_command(self, kin: KinState) -> Command:
        land_m_s = self.params.get("MPC_LAND_SPEED")
        if not self.position_valid:
            return Command(0.0, 0.0, land_m_s)
        hold = hold_command(kin, self.hold_ned_m)
        return Command(hold.vn_m_s, hold.ve_m_s, land_m_s)

    def _takeoff_command(self, kin: KinState) -> Command:
        hold = hold_command(kin, self.hold_ned_m)
        climb_m_s = min(self.params.get("MPC_TKO_SPEED"), POSITION_GAIN_1_S * (kin.d_m - self.takeoff_d_m) + 0.2)
        if kin.d_m <= self.takeoff_d_m + TAKEOFF_DONE_M:
            self._enter(px4.HOLD, by_user=False)
            self.hold_ned_m = (kin.n_m, kin.e_m, self.takeoff_d_m)
            return hold_command(kin, self.hold_ned_m)
        return Command(hold.vn_m_s, hold.ve_m_s, -climb_m_s)

    # ---- telemetry -----------------------------------------------------------------------
    def landed_state(self, kin: KinState) -> int:
        """EXTENDED_SYS_STATE.landed_state for the current mode and physics state."""
        if kin.on_ground or (not self.armed and self.now_s - self.disarm_t_s >= self.params.get("LNDMC_TRIG_TIME") / 3):
            return px4.LANDED_ON_GROUND
        if self.mode == "AUTO.TAKEOFF":
            return px4.LANDED_TAKEOFF
        if self.mode == "AUTO.LAND" or self._needs_pilot(self.mode) or (self.mode == "AUTO.RTL" and self.rtl_phase == "land"):
            return px4.LANDED_LANDING
        return px4.LANDED_IN_AIR

    def system_status(self) -> int:
        if self.in_failsafe:
            return px4.MAV_STATE_CRITICAL
        return px4.MAV_STATE_ACTIVE if self.armed else px4.MAV_STATE_STANDBY

    def armable(self) -> bool:
        """The PREARM_CHECK health bit: arming would pass the checks in the current mode."""
        return not self.refuse_arming_reason and self.position_valid and not self._needs_pilot(self.mode)


def offboard_command(kin: KinState, sp: TrajectorySetpoint) -> Command:
    """The trajectory setpoint as it is: PX4's position controller flies it unsmoothed."""
    vn, ve, vd = sp.velocity
    return Command(vn, ve, vd, sp.yaw_rad, sp.yaw_rate_rad_s, position_ned_m=sp.position,
                   acceleration_ned_m_s2=sp.acceleration)


def hold_command(kin: KinState, target_ned_m: tuple[float, float, float], yaw_rad: float | None = None) -> Command:
    """Position P loop towards ``target_ned_m`` [m] (limits apply in the physics)."""
    k = POSITION_GAIN_1_S
    return Command(k * (target_ned_m[0] - kin.n_m), k * (target_ned_m[1] - kin.e_m),
                   k * (target_ned_m[2] - kin.d_m), yaw_rad)


def rtl_return_d_m(params: ParamTable, home_ned_m: tuple[float, float, float], kin: KinState) -> float:
    """RTL's return altitude as NED down [m] towards ``home_ned_m`` from ``kin`` (PX4's
    ``computeReturnAltitude`` for a multicopter; see the module docstring)."""
    p = params.get
    home_n, home_e, home_d = home_ned_m
    dist_m = math.hypot(home_n - kin.n_m, home_e - kin.e_m)
    highest = p("RTL_RETURN_ALT")
    cone_deg = p("RTL_CONE_ANG")
    if cone_deg <= 0:
        return min(kin.d_m, home_d - highest)
    acc_rad = p("NAV_ACC_RAD")
    if dist_m <= acc_rad:
        height = 2.0 * dist_m
    else:
        height = highest
        if dist_m <= p("RTL_MIN_DIST"):
            height = min(dist_m / math.tan(math.radians(min(max(cone_deg, 1.0), 89.0))), height)
        height = max(height, 2.0 * acc_rad)
    return min(max(home_d - height, home_d - highest), kin.d_m)  # no lower than the vehicle is


def rtl_command(c: Commander, kin: KinState) -> Command:
    """RTL: climb to the return altitude, fly to the destination fixed at the start at
    MPC_XY_CRUISE, descend and land (``c.rtl_phase``: climb, return, land)."""
    home_n, home_e, _ = c.rtl_home_ned_m
    dist_m = math.hypot(home_n - kin.n_m, home_e - kin.e_m)
    if c.rtl_phase == "climb":
        if dist_m <= 2 * ARRIVAL_RADIUS_M:
            c.rtl_phase = "land"
        elif kin.d_m <= c.rtl_return_d_m + ARRIVAL_RADIUS_M:
            c.rtl_phase = "return"
        else:
            return hold_command(kin, (c.hold_ned_m[0], c.hold_ned_m[1], c.rtl_return_d_m))
    if c.rtl_phase == "return":
        if dist_m > ARRIVAL_RADIUS_M:
            gain = min(c.params.get("MPC_XY_CRUISE"), POSITION_GAIN_1_S * dist_m) / dist_m
            return Command(gain * (home_n - kin.n_m), gain * (home_e - kin.e_m),
                           POSITION_GAIN_1_S * (c.rtl_return_d_m - kin.d_m))
        c.rtl_phase = "land"
    if c.rtl_phase == "land" and c.hold_ned_m[:2] != (home_n, home_e) and dist_m <= 2 * ARRIVAL_RADIUS_M:
        c.hold_ned_m = (home_n, home_e, kin.d_m)
    return c.descend_command(kin)
