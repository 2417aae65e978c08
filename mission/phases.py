"""The mission state machine (pure): observations in, phase + setpoint + request out.

::

    PREFLIGHT --vehicle, position, carrier fresh; geometry ok--> STREAMING
        |  geometry breaks the paper's assumptions --> ABORT(geometry)  (nothing was sent)
    STREAMING --zero-velocity setpoints for prestream_s--> ARMING (or OFFBOARD if armed)
    ARMING    --armed--> OFFBOARD           refused after retries --> ABORT(arming_refused)
    OFFBOARD  --mode is OFFBOARD--> JOIN    refused after retries --> ABORT(offboard_refused)
    JOIN      --reference on the dock point, vehicle within join_settle_m for join_settle_s--> RIDING
    RIDING    --docked carrier within b c - margin of the target (latched)--> SEPARATED
    SEPARATED --passenger left the dock (> 0.1 m)--> NAVIGATING
    NAVIGATING --within arrival radius for arrival dwell--> ARRIVED
    ARRIVED   --request Hold or Land--> HOLD | LAND --vehicle shows that mode--> DONE

    any phase --> ABORT(reason): vehicle_lost, pilot_override, vehicle_failsafe (PX4 left
                  OFFBOARD for one of its own failsafes), carrier_lost, position_lost,
                  arming_refused, offboard_refused, geometry, interrupted, timeout,
                  signing_mismatch (no vehicle by connect_timeout_s, but a PX4 autopilot was
                  heard signing with another key: ``failed["signing"]`` says which)
    ABORT requests Hold (never disarm in the air) unless the vehicle is lost or a pilot took
    over or PX4 runs its own failsafe (then nothing is sent: never fight either); setpoints stop
    once Hold is shown.

The passenger is flown through a *reference*: the paper's closed loop (``mission.tick``, the
same functions as the simulator) integrated in error coordinates about the dock point, which the
vehicle tracks (:mod:`mission.tracking`: velocity ``u_ref + track_gain (x_ref - x_p)``, and for
full setpoints also the reference position and an acceleration feed-forward: the reference's own
acceleration, which while riding is the carrier law's, plus drag feed-forward and integral). The reference sits exactly on the
dock while riding, so separation happens at ``b c`` whatever the vehicle's tracking lag
(README, "Facts about the law" 3), and its departure is smooth. The carrier's state is needed until
separation; afterwards the anchor is latched and a lost carrier only costs P3 monitoring.

Frames: local NED [m], [m/s]; times [s] on the controller's clock.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from enum import Enum

import numpy as np

from mission.law import check_assumptions, norm
from mission.ports import Request
from mission.errors import AssumptionError
from mission.safety import SafetyConfig, filter_velocity
from mission.tick import DEPARTURE_THRESHOLD_M, TickModel, carrier_tick, latch_point, passenger_tick, separation_due
from mission.tracking import TrackingGains, progress, setpoint as tracking_setpoint, update_integral, velocity_demand

TELEMETRY_SILENT_S = 0.4  # position older than this (PX4 streams it at 30 Hz): the link went quiet [s]


class Phase(str, Enum):
    PREFLIGHT = "PREFLIGHT"
    STREAMING = "STREAMING"
    ARMING = "ARMING"
    OFFBOARD = "OFFBOARD"
    JOIN = "JOIN"
    RIDING = "RIDING"
    SEPARATED = "SEPARATED"
    NAVIGATING = "NAVIGATING"
    ARRIVED = "ARRIVED"
    HOLD = "HOLD"
    LAND = "LAND"
    DONE = "DONE"
    ABORT = "ABORT"


class AbortReason(str, Enum):
    VEHICLE_LOST = "vehicle_lost"
    PILOT_OVERRIDE = "pilot_override"
    VEHICLE_FAILSAFE = "vehicle_failsafe"
    CARRIER_LOST = "carrier_lost"
    POSITION_LOST = "position_lost"
    ARMING_REFUSED = "arming_refused"
    OFFBOARD_REFUSED = "offboard_refused"
    GEOMETRY = "geometry"
    INTERRUPTED = "interrupted"
    TIMEOUT = "timeout"
    SIGNING_MISMATCH = "signing_mismatch"


# Phases in which the vehicle is ours in OFFBOARD and must stay there.
FLYING = {Phase.JOIN, Phase.RIDING, Phase.SEPARATED, Phase.NAVIGATING, Phase.ARRIVED}
BEFORE_SEPARATION = {Phase.PREFLIGHT, Phase.STREAMING, Phase.ARMING, Phase.OFFBOARD, Phase.JOIN, Phase.RIDING}


@dataclass(frozen=True)
class VehicleObs:
    """The vehicle as the link sees it: position/velocity [m], [m/s] NED; HEARTBEAT and
    LOCAL_POSITION_NED ages [s]."""

    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    armed: bool
    mode: str
    heartbeat_age_s: float
    position_valid: bool = True
    position_age_s: float = 0.0
    in_failsafe: bool = False  # HEARTBEAT system_status CRITICAL: PX4 runs one of its failsafes


@dataclass(frozen=True)
class CarrierObs:
    """The carrier's newest state: position/velocity NED [m], [m/s]; age [s]; liveliness."""

    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    age_s: float
    alive: bool | None = True


@dataclass(frozen=True)
class Observation:
    """What one tick sees. ``failed`` maps a request ("arm", "offboard") to the vehicle's reason
    once the controller gave up on it after its retries."""

    t_s: float
    vehicle: VehicleObs | None
    carrier: CarrierObs | None
    failed: dict[str, str] = field(default_factory=dict)
    interrupted: bool = False


@dataclass(frozen=True)
class MissionModel:
    """Fixed parameters of a mission (built from the config by the controller)."""

    tick: TickModel
    command_safety: SafetyConfig  # limits on what is sent to the vehicle
    dock_offset_ned_m: np.ndarray
    dock_tolerance_m: float
    track_gain: float
    join_speed_m_s: float
    arrival_radius_m: float
    arrival_dwell_s: float
    final_action: str  # "hold" | "land"
    carrier_timeout_s: float
    heartbeat_timeout_s: float
    prestream_s: float
    connect_timeout_s: float
    max_duration_s: float
    dt_s: float
    tracking: TrackingGains = TrackingGains()
    join_settle_m: float = float("inf")  # JOIN -> RIDING within this of the dock point [m] (min with the tolerance)...
    join_settle_s: float = 0.0  # ... for this long [s]
    arrival_max_speed_m_s: float | None = None  # arrival also needs the vehicle this slow [m/s]
    carrier_dt_s: float = 1.0 / 30.0  # the carrier's control period [s] (its acceleration over one step)


@dataclass(frozen=True)
class MissionState:
    """Everything the machine remembers between ticks (immutable; ``step`` returns a new one)."""

    phase: Phase = Phase.PREFLIGHT
    since_s: float = 0.0
    start_s: float | None = None
    reason: str = ""
    detail: str = ""
    x_ref: np.ndarray | None = None  # reference passenger position [m] NED
    e_ref: np.ndarray | None = None  # reference error to the anchor [m]
    anchor: np.ndarray | None = None  # latched anchor after separation [m]
    prev_dock: np.ndarray | None = None
    separation_time_s: float | None = None
    arrived_since_s: float | None = None
    u_ref: np.ndarray | None = None
    u_cmd: np.ndarray | None = None
    integral: np.ndarray | None = None  # tracking integral (mission.tracking)
    settled_since_s: float | None = None  # JOIN: since when the vehicle has been on the dock point


@dataclass(frozen=True)
class Decision:
    """What the controller does this tick. setpoint [m/s] NED or None (send nothing);
    request: the vehicle command to have in flight (:class:`~mission.ports.Request`) or None.
    Diagnostics for the flight log: dock, P, relative (law's u_p - u_c), desired, safety_acted."""

    setpoint: np.ndarray | None
    request: Request | None = None
    position_sp: np.ndarray | None = None  # [m] NED: with acceleration_sp, a full setpoint
    acceleration_sp: np.ndarray | None = None  # [m/s^2] NED
    dock: np.ndarray | None = None
    P: float = float("nan")
    relative: np.ndarray | None = None
    desired: np.ndarray | None = None
    safety_acted: bool = False
    events: tuple[str, ...] = ()


ZERO = np.zeros(3)


def _to(state: MissionState, phase: Phase, t: float, **kw) -> MissionState:
    return replace(state, phase=phase, since_s=t, **kw)


def _abort(state: MissionState, t: float, reason: AbortReason, detail: str = "") -> MissionState:
    return replace(state, phase=Phase.ABORT, since_s=t, reason=reason.value, detail=detail)


def _vehicle_lost(v: VehicleObs | None, m: MissionModel) -> bool:
    """No HEARTBEAT for heartbeat_timeout_s while the position stream is silent too. PX4 sends
    HEARTBEAT at 1 Hz: on a link losing 30% of its packets three in a row go missing in most
    flights, while the 30 Hz LOCAL_POSITION_NED shows the vehicle is there (its mode is then
    up to a few seconds old, which only delays noticing a pilot's takeover)."""
    return v is None or (v.heartbeat_age_s > m.heartbeat_timeout_s and v.position_age_s > TELEMETRY_SILENT_S)


def _carrier_ok(obs: Observation, m: MissionModel) -> bool:
    c = obs.carrier
    return c is not None and c.age_s <= m.carrier_timeout_s and c.alive is not False


def _hold_decision(state: MissionState, obs: Observation) -> Decision:
    """Ask for Hold; keep zero-velocity setpoints flowing until the vehicle shows it (so a
    switch that is slow to take effect never leaves OFFBOARD without setpoints)."""
    v = obs.vehicle
    if v is not None and v.mode == "OFFBOARD":
        return Decision(setpoint=ZERO.copy(), request=Request.HOLD)
    return Decision(setpoint=None, request=Request.HOLD if v is not None and v.mode != "AUTO.LOITER" and v.armed else None)


def step(state: MissionState, obs: Observation, m: MissionModel) -> tuple[MissionState, Decision]:
    """Advance the mission by one tick. Pure: same inputs, same outputs."""
    t = obs.t_s
    if state.start_s is None:
        state = replace(state, start_s=t, since_s=t)
    state, early = _failsafes(state, obs, m)
    if early is not None:
        return state, early
    handler = _HANDLERS[state.phase]
    return handler(state, obs, m)


def _failsafes(state: MissionState, obs: Observation, m: MissionModel) -> tuple[MissionState, Decision | None]:
    """Transitions that any phase can take, checked before the phase's own logic."""
    t, v, ph = obs.t_s, obs.vehicle, state.phase
    if ph in (Phase.DONE,):
        return state, Decision(setpoint=None)
    if ph == Phase.ABORT:
        if _vehicle_lost(v, m):
            return state, Decision(setpoint=None)  # nobody to talk to: PX4's own failsafe acts
        if state.reason in (AbortReason.VEHICLE_LOST.value, AbortReason.PILOT_OVERRIDE.value,
                            AbortReason.VEHICLE_FAILSAFE.value, AbortReason.GEOMETRY.value):
            return state, Decision(setpoint=None)
        return state, _hold_decision(state, obs)
    if obs.interrupted:
        new = _abort(state, t, AbortReason.INTERRUPTED, "signal")
        return new, _decided(new, obs, "abort: interrupted")
    if ph != Phase.PREFLIGHT and _vehicle_lost(v, m):
        new = _abort(state, t, AbortReason.VEHICLE_LOST, "no HEARTBEAT")
        return new, Decision(setpoint=None, events=("abort: vehicle heartbeat lost",))
    final_modes = ("AUTO.LOITER", "AUTO.LAND")
    if ph in FLYING and v is not None and v.mode != "OFFBOARD" and not (ph == Phase.ARRIVED and v.mode in final_modes):
        reason = AbortReason.VEHICLE_FAILSAFE if v.in_failsafe else AbortReason.PILOT_OVERRIDE
        new = _abort(state, t, reason, f"vehicle switched to {v.mode}")
        return new, Decision(setpoint=None, events=(f"abort: vehicle left OFFBOARD ({v.mode}); not fighting it",))
    if ph not in (Phase.PREFLIGHT,) and v is not None and not v.position_valid:
        if TELEMETRY_SILENT_S < v.position_age_s <= m.heartbeat_timeout_s:
            # The position stream went quiet (a link blackout, not an estimator failure): hover
            # until the heartbeat timeout decides whether the vehicle is lost.
            return state, Decision(setpoint=ZERO.copy(), events=("telemetry silent",))
        new = _abort(state, t, AbortReason.POSITION_LOST, "position estimate invalid")
        return new, _decided(new, obs, "abort: position estimate lost")
    if ph in BEFORE_SEPARATION - {Phase.PREFLIGHT} and not _carrier_ok(obs, m):
        new = _abort(state, t, AbortReason.CARRIER_LOST, _carrier_detail(obs, m))
        return new, _decided(new, obs, "abort: carrier state lost before separation")
    if state.start_s is not None and t - state.start_s > m.max_duration_s and ph not in (Phase.HOLD, Phase.LAND):
        new = _abort(state, t, AbortReason.TIMEOUT, f"mission longer than {m.max_duration_s:g} s")
        return new, _decided(new, obs, "abort: mission timeout")
    return state, None


def _decided(state: MissionState, obs: Observation, event: str) -> Decision:
    d = _hold_decision(state, obs)
    return replace(d, events=(event,))


def _carrier_detail(obs: Observation, m: MissionModel) -> str:
    c = obs.carrier
    if c is None:
        return "no carrier state received"
    if c.alive is False:
        return "carrier liveliness token gone"
    return f"carrier state {c.age_s:.2f} s old (limit {m.carrier_timeout_s:g} s)"


def _dock(obs: Observation, m: MissionModel) -> np.ndarray:
    """Dock point [m] NED now: the carrier's last position moved on by its velocity over the
    sample's age (a late sample would otherwise pull the passenger back by speed x age), plus
    the dock offset."""
    c = obs.carrier
    assert c is not None  # every caller checked it
    return c.position_ned_m + c.velocity_ned_m_s * c.age_s + m.dock_offset_ned_m


def live_geometry_problem(dock: np.ndarray, vehicle_ned_m: np.ndarray, m: MissionModel) -> str | None:
    """What is wrong with the live geometry at start-up, in terms of what the user controls (the
    carrier's and the vehicle's positions, config fields), or None. The paper's conditions on the
    states the controller sees: the docked carrier farther than ``b c`` from the target, the target
    within ``b c`` of the planar carrier's plane, the vehicle on the carrier (Assumptions 1-2)."""
    bc = m.tick.law.separation_distance_m
    target = m.tick.target
    dist = float(norm(target - dock))
    where = np.round(dock - m.dock_offset_ned_m, 2).tolist()
    if dist <= bc:
        return (f"the carrier (at {where} NED) is already {dist:.2f} m from the target, inside b*c = {bc:g} m "
                f"(its dock point would separate the passenger at once): restart the carrier "
                f"(`marsupial carrier` starts at scenario.carrier_start) or move it more than {bc:g} m from the target")
    if m.tick.planar_carrier:
        height = abs(float(target[2] - dock[2]))
        if height > bc:
            return (f"the target is {height:.2f} m above the dock point, more than b*c = {bc:g} m: the carrier can never "
                    f"come within b*c of it; lower scenario.target or change mission.dock_offset_ned_m")
    horizontal = float(norm((vehicle_ned_m - dock)[:2]))
    if horizontal > m.dock_tolerance_m:
        return (f"the vehicle (at {np.round(vehicle_ned_m, 2).tolist()} NED) is {horizontal:.2f} m from the carrier's "
                f"dock point horizontally, more than mission.dock_tolerance_m = {m.dock_tolerance_m:g} m "
                f"(Assumption 2: the passenger starts on the carrier): put the vehicle on the carrier (land it there; "
                f"a mock vehicle: restart `marsupial mock-vehicle`, --start-ned N,E,D) or restart the carrier "
                f"under it (scenario.carrier_start)")
    return None


def _preflight(state: MissionState, obs: Observation, m: MissionModel) -> tuple[MissionState, Decision]:
    t, v = obs.t_s, obs.vehicle
    ready = v is not None and v.heartbeat_age_s <= m.heartbeat_timeout_s and v.position_valid and _carrier_ok(obs, m)
    if not ready:
        if t - state.since_s > m.connect_timeout_s:
            why = "no vehicle" if v is None else ("no carrier" if not _carrier_ok(obs, m) else "vehicle not ready")
            reason = AbortReason.VEHICLE_LOST if v is None else AbortReason.CARRIER_LOST
            if v is None and "signing" in obs.failed:
                why, reason = obs.failed["signing"], AbortReason.SIGNING_MISMATCH
            new = _abort(state, t, reason, why)
            return new, Decision(setpoint=None, events=(f"abort: preflight: {why}",))
        return state, Decision(setpoint=None)
    assert v is not None  # ready
    dock = _dock(obs, m)
    problem = live_geometry_problem(dock, v.position_ned_m, m)
    if problem is None:
        try:
            check_assumptions(dock, m.tick.target, m.tick.law, planar_carrier=m.tick.planar_carrier, field_prefix="mission")
        except AssumptionError as exc:
            problem = str(exc)
    if problem is not None:
        new = _abort(state, t, AbortReason.GEOMETRY, problem)
        return new, Decision(setpoint=None, events=(f"abort: geometry: {problem}",))
    new = _to(state, Phase.STREAMING, t)
    return new, Decision(setpoint=ZERO.copy(), dock=dock, events=("preflight ok",))


def _streaming(state, obs, m):
    t = obs.t_s
    if t - state.since_s >= m.prestream_s:
        nxt = Phase.OFFBOARD if obs.vehicle.armed else Phase.ARMING
        return _to(state, nxt, t), Decision(setpoint=ZERO.copy(), request=Request.OFFBOARD if nxt == Phase.OFFBOARD else Request.ARM)
    return state, Decision(setpoint=ZERO.copy())


def _arming(state, obs, m):
    t = obs.t_s
    if Request.ARM in obs.failed:
        new = _abort(state, t, AbortReason.ARMING_REFUSED, obs.failed[Request.ARM])
        return new, Decision(setpoint=None, events=(f"abort: arming refused: {obs.failed['arm']}",))
    if obs.vehicle.armed:
        return _to(state, Phase.OFFBOARD, t), Decision(setpoint=ZERO.copy(), request=Request.OFFBOARD)
    return state, Decision(setpoint=ZERO.copy(), request=Request.ARM)


def _offboard(state, obs, m):
    t, v = obs.t_s, obs.vehicle
    if Request.OFFBOARD in obs.failed:
        new = _abort(state, t, AbortReason.OFFBOARD_REFUSED, obs.failed[Request.OFFBOARD])
        return new, _decided(new, obs, f"abort: OFFBOARD refused: {obs.failed['offboard']}")
    if v.mode == "OFFBOARD":
        new = _to(state, Phase.JOIN, t, x_ref=v.position_ned_m.copy(), u_cmd=ZERO.copy())
        return new, Decision(setpoint=ZERO.copy())
    return state, Decision(setpoint=ZERO.copy(), request=Request.OFFBOARD)


@dataclass(frozen=True)
class Tracked:
    """One tick of tracking: what to send (velocity [m/s]; for a full setpoint also position [m]
    and acceleration [m/s^2]), whether the filter changed the velocity, and what the state keeps
    (the velocity sent, the integral)."""

    setpoint: np.ndarray
    position_sp: np.ndarray | None
    acceleration_sp: np.ndarray | None
    acted: bool
    integral: np.ndarray

    def decision(self, **kw) -> Decision:
        return Decision(setpoint=self.setpoint, position_sp=self.position_sp, acceleration_sp=self.acceleration_sp, **kw)

    def kept(self) -> dict[str, np.ndarray]:
        return {"u_cmd": self.setpoint, "integral": self.integral}


def _track(state: MissionState, obs: Observation, m: MissionModel, x_ref: np.ndarray, u_ref: np.ndarray,
           a_ref: np.ndarray) -> Tracked:
    """The setpoint that makes the vehicle follow the reference (:mod:`mission.tracking`): the
    velocity demand filtered at the vehicle's real position (obstacles, floor, speed and
    acceleration of the vehicle); a full setpoint adds the reference position and the
    acceleration feed-forward, unless the filter changed the velocity (then the filtered
    velocity alone is sent: the filter wins over the reference)."""
    v = obs.vehicle
    assert v is not None  # tracking happens only with a vehicle
    x_p = v.position_ned_m
    g = m.tracking
    integral = state.integral if state.integral is not None else np.zeros(3)
    desired = velocity_demand(x_ref, u_ref, x_p, integral, g)
    prev = state.u_cmd if state.u_cmd is not None else v.velocity_ned_m_s
    safe = filter_velocity(x_p, desired, m.tick.obstacles, m.command_safety, prev, m.dt_s)
    acted = bool(safe.changed)
    sp = tracking_setpoint(x_ref, u_ref, a_ref, x_p, safe.u, integral, g)
    full = sp.full and not acted
    if not acted or g.kind == "velocity":
        integral = update_integral(integral, x_ref, x_p, g, m.dt_s)
    return Tracked(sp.velocity_ned_m_s, sp.position_ned_m if full else None, sp.acceleration_ned_m_s2 if full else None,
                   acted, integral)


def _carrier_acceleration(obs: Observation, m: MissionModel) -> np.ndarray:
    """The docked carrier's acceleration [m/s^2] NED as its law asks it: the change of the
    carrier's command (``mission.tick.carrier_tick``, with its speed and acceleration limits)
    over one carrier step from the sample's state. Analytic in the sample (no differences of
    samples): ``a_max`` along the command while the carrier speeds up, 0 at its speed limit,
    ``-k_c v_c`` on the final approach."""
    c = obs.carrier
    assert c is not None  # riding: the carrier was checked
    h = m.carrier_dt_s
    nxt = carrier_tick(c.position_ned_m + c.velocity_ned_m_s * h, False, m.tick, u_prev=c.velocity_ned_m_s, dt_s=h)
    return (np.asarray(nxt.u, dtype=float) - c.velocity_ned_m_s) / h


def _join(state, obs, m):
    """Move the reference from where the vehicle took over to the dock point at join speed."""
    t = obs.t_s
    dock = _dock(obs, m)
    v_dock = obs.carrier.velocity_ned_m_s
    gap = dock - state.x_ref
    dist = float(norm(gap))
    step_len = m.join_speed_m_s * m.dt_s
    if dist <= step_len:
        x_ref, u_ref = dock.copy(), v_dock.copy()
    else:
        u_ref = gap / dist * m.join_speed_m_s + v_dock
        x_ref = state.x_ref + u_ref * m.dt_s
    tr = _track(state, obs, m, x_ref, u_ref, ZERO)
    # Docked once the vehicle has settled on the dock point (within join_settle_m for
    # join_settle_s): the carrier starts its approach then, so what is left of the climb is not
    # counted as riding offset (on PX4 the climb overshoots the dock by ~0.3 m when first within
    # tolerance, and its velocity estimate is too noisy to judge rest by).
    v = obs.vehicle
    near = dist <= step_len and norm(v.position_ned_m - dock) <= m.join_settle_m
    settled = (state.settled_since_s if state.settled_since_s is not None else t) if near else None
    if settled is not None and t - settled >= m.join_settle_s:
        new = _to(state, Phase.RIDING, t, x_ref=dock.copy(), e_ref=ZERO.copy(), prev_dock=dock.copy(), u_ref=v_dock.copy(), **tr.kept())
        return new, tr.decision(dock=dock, desired=u_ref, safety_acted=tr.acted, events=("docked: riding the carrier",))
    return (replace(state, x_ref=x_ref, u_ref=u_ref, settled_since_s=settled, **tr.kept()),
            tr.decision(dock=dock, desired=u_ref, safety_acted=tr.acted))


def _riding(state, obs, m):
    """Equilibrium (i): the reference stays exactly on the dock; the latch fires at b c - margin."""
    t = obs.t_s
    dock = _dock(obs, m)
    v_dock = obs.carrier.velocity_ned_m_s
    if separation_due(dock, False, m.tick):
        theta, anchor = latch_point(state.prev_dock, dock, m.tick.target, m.tick)
        new = _to(state, Phase.SEPARATED, t, anchor=anchor, e_ref=ZERO.copy(), x_ref=anchor.copy(),
                  separation_time_s=t - (1 - float(theta)) * m.dt_s)
        return _navigate(new, obs, m, events=(f"separated at |e_tc| = {norm(m.tick.target - anchor):.3f} m",))
    tick = passenger_tick(dock, v_dock, ZERO, False, m.tick, state.u_ref, m.dt_s)
    a_ref = _carrier_acceleration(obs, m) if m.tracking.kind == "full" else ZERO  # velocity setpoints carry none
    tr = _track(state, obs, m, dock, tick.u, a_ref)
    acted = tr.acted
    new = replace(state, x_ref=dock.copy(), e_ref=ZERO.copy(), prev_dock=dock.copy(), u_ref=tick.u, **tr.kept())
    return new, tr.decision(dock=dock, P=float(tick.P), relative=tick.relative, desired=tick.desired,
                         safety_acted=acted or bool(tick.safety.changed))


def _lag_m(state: MissionState, obs: Observation) -> float:
    """How far [m] the vehicle is behind the reference along the reference's direction of motion
    (0 when it is level or ahead, or the reference is still)."""
    if state.x_ref is None or state.u_ref is None or obs.vehicle is None:
        return 0.0
    speed = float(norm(state.u_ref))
    if speed < 1e-6:
        return 0.0
    return max(0.0, float(np.dot(state.x_ref - obs.vehicle.position_ned_m, state.u_ref)) / speed)


def _navigate(state, obs, m, events=()):
    """Equilibria (ii)->(iii): integrate the reference with the latched anchor, track it."""
    t = obs.t_s
    tick = passenger_tick(state.anchor, ZERO, state.e_ref, True, m.tick, state.u_ref, m.dt_s)
    # The reference advances at the rate the vehicle can follow (mission.tracking.progress); its
    # acceleration is its own velocity's change over the tick (a signal we generate: no noise).
    rate = progress(_lag_m(state, obs), m.tracking)
    u_ref = tick.u * rate
    e_ref = state.e_ref + u_ref * m.dt_s
    x_ref = state.anchor + e_ref
    u_prev = state.u_ref if state.u_ref is not None else u_ref
    a_ref = (u_ref - u_prev) / m.dt_s
    tr = _track(state, obs, m, x_ref, u_ref, a_ref)
    acted = tr.acted
    phase, since, arrived = state.phase, state.since_s, state.arrived_since_s
    evs = list(events)
    if phase == Phase.SEPARATED and norm(e_ref) > DEPARTURE_THRESHOLD_M:
        phase, since = Phase.NAVIGATING, t
        evs.append("left the carrier: navigating")
    # Arrived: within the arrival radius (and, if set, slower than arrival_max_speed_m_s) for the
    # dwell (a vehicle handed to Hold while still moving brakes past the radius: seen on PX4, 0.84 m).
    at_target = bool(norm(obs.vehicle.position_ned_m - m.tick.target) <= m.arrival_radius_m) and (
        m.arrival_max_speed_m_s is None or bool(norm(obs.vehicle.velocity_ned_m_s) <= m.arrival_max_speed_m_s))
    if phase in (Phase.NAVIGATING,):
        arrived = (arrived if arrived is not None else t) if at_target else None
        if arrived is not None and t - arrived >= m.arrival_dwell_s:
            phase, since = Phase.ARRIVED, t
            evs.append("arrived at the target")
    new = replace(state, phase=phase, since_s=since, e_ref=e_ref, x_ref=x_ref, u_ref=u_ref, arrived_since_s=arrived, **tr.kept())
    dec = tr.decision(dock=_dock(obs, m) if obs.carrier is not None else None, P=float(tick.P),
                   relative=tick.relative, desired=tick.desired, safety_acted=acted or bool(tick.safety.changed), events=tuple(evs))
    if phase == Phase.ARRIVED:
        dec = replace(dec, request=Request(m.final_action))
    return new, dec


def _arrived(state, obs, m):
    t, v = obs.t_s, obs.vehicle
    want = "AUTO.LOITER" if m.final_action == Request.HOLD else "AUTO.LAND"
    if v.mode == want:
        nxt = Phase.HOLD if m.final_action == Request.HOLD else Phase.LAND
        return _to(state, nxt, t), Decision(setpoint=None, events=(f"vehicle in {want}",))
    new, dec = _navigate(state, obs, m)
    return replace(new, phase=Phase.ARRIVED, since_s=state.since_s), replace(dec, request=Request(m.final_action))


def _final(state, obs, m):
    return _to(state, Phase.DONE, obs.t_s), Decision(setpoint=None, events=("mission complete",))


def finished(state: MissionState, decision: Decision) -> bool:
    """True when the controller loop may stop: DONE, or ABORT with nothing left to send."""
    if state.phase == Phase.DONE:
        return True
    return state.phase == Phase.ABORT and decision.setpoint is None and decision.request is None


_HANDLERS = {
    Phase.PREFLIGHT: _preflight,
    Phase.STREAMING: _streaming,
    Phase.ARMING: _arming,
    Phase.OFFBOARD: _offboard,
    Phase.JOIN: _join,
    Phase.RIDING: _riding,
    Phase.SEPARATED: _navigate,
    Phase.NAVIGATING: _navigate,
    Phase.ARRIVED: _arrived,
    Phase.HOLD: _final,
    Phase.LAND: _final,
}
