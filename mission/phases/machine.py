"""The mission state machine (pure): observations in, phase + setpoint + request out.

::

    PREFLIGHT --vehicle, position, carrier fresh; geometry ok--> STREAMING
        |  geometry breaks the paper's assumptions --> ABORT(geometry)  (nothing was sent)
    STREAMING --zero-velocity setpoints for prestream_s--> ARMING (or OFFBOARD if armed)
    ARMING    --armed--> OFFBOARD           refused after retries --> ABORT(arming_refused)
    OFFBOARD  --mode is OFFBOARD--> JOIN    refused after retries --> ABORT(offboard_refused)
    JOIN      --reference on the dock point, vehicle within join_settle_m for join_settle_s (with [relnav],
               the estimate's jumps taken in: relnav.pending_limit_m)--> RIDING
    RIDING    --docked carrier within b c - margin of the target (latched)--> SEPARATED
    SEPARATED --passenger left the dock (> 0.1 m)--> NAVIGATING
    NAVIGATING --within arrival radius for arrival dwell--> ARRIVED
    ARRIVED   --request Hold or Land--> HOLD | LAND --vehicle shows that mode--> DONE

    before separation (JOIN .. RIDING, TRANSIT), a carrier state older than
                  mission.carrier_timeout_s (a stalled carrier process or link) --the phase goes
                  on, on the dock point predicted with the state's age; no separation on it
                  (the latch waits for a fresh state)
    any phase --> ABORT(reason): vehicle_lost, pilot_override, vehicle_failsafe (PX4 left
                  OFFBOARD for one of its own failsafes), carrier_lost (before separation: the
                  carrier's liveliness token gone, or no fresh state for mission.carrier_lost_s),
                  position_lost,
                  arming_refused, offboard_refused, geometry, interrupted, timeout,
                  signing_mismatch (no vehicle by connect_timeout_s, but a PX4 autopilot was
                  heard signing with another key: ``failed["signing"]`` says which),
                  vehicle_ambiguous (a second PX4 autopilot was heard with
                  mavlink.target_system unset: ``failed["identity"]`` says which),
                  nonfinite (a NaN or infinity in what the tick would send or keep: the
                  reference, the setpoint; it names which, and the tick asks for Hold instead)
    ARMED phases (OFFBOARD and every flying one) --vehicle disarmed--> ABORT(vehicle_disarmed)
    AIRBORNE phases (the flying ones but JOIN, DOCKED, HOME) --vehicle landed (ON_GROUND)-->
                  ABORT(vehicle_disarmed)
    ... except while the passenger sits on the deck (mission.ride = "deck", state.seated;
    mission.phases.deck): landed, disarmed and out of OFFBOARD are then where it is; taking off
    (SEPARATED, NAVIGATING still seated) it must be armed and in OFFBOARD
    seated, the mission asking nothing --armed after disarmed, another mode, or off the deck-->
                  ABORT(deck_disturbed) (mission.phases.deck.watch)
    ABORT requests Hold (never disarm in the air) unless the vehicle is lost or disarmed, a
    pilot took over or PX4 runs its own failsafe (then nothing is sent: never fight, and never
    stream to a vehicle that someone else disarmed); setpoints stop once Hold is shown. ABORT is
    final: a vehicle re-armed by someone else is not flown again.

The passenger is flown through a *reference*: the paper's closed loop (:mod:`mission.core.tick`,
the same functions as the simulator) integrated in error coordinates about the dock point, which
the vehicle tracks (:mod:`mission.core.tracking`). The reference sits exactly on the dock while
riding, so separation happens at ``b c`` whatever the vehicle's tracking lag (docs/how-it-works.md,
facts about the law 3). The carrier's state is needed until separation; afterwards the anchor is
latched and a lost carrier only costs P3 monitoring.

Frames: local NED [m], [m/s]; times [s] on the controller's clock.
"""
from __future__ import annotations

from mission.core.records import replace

import numpy as np

from mission.flight_mode import FlightMode
from mission.errors import AssumptionError
from mission.core.law import check_assumptions, norm
from mission.core.setpoint import Setpoint
from mission.phases.phase import AIRBORNE, ARMED, BEFORE_SEPARATION, FLYING, Phase, Request
from mission.phases.types import (
    TELEMETRY_SILENT_S,
    ZERO,
    AbortReason,
    CarrierObs,
    Decision,
    MissionModel,
    MissionState,
    Observation,
    VehicleObs,
    carrier_fresh,
    describe_age,
    dock_point,
    enter,
)
from mission.phases import battery, deck, recovery, stall
from mission.phases.flying import arrived, join, navigate, riding

__all__ = [
    "AIRBORNE", "ARMED", "BEFORE_SEPARATION", "FLYING", "TELEMETRY_SILENT_S", "AbortReason", "CarrierObs", "Decision", "MissionModel",
    "MissionState", "Observation", "Phase", "VehicleObs", "finished", "live_geometry_problem", "step",
]


def _abort(state: MissionState, t: float, reason: AbortReason, detail: str = "") -> MissionState:
    return replace(state, phase=Phase.ABORT, since_s=t, reason=reason, detail=detail)


def _vehicle_lost(v: VehicleObs | None, m: MissionModel) -> bool:
    """No HEARTBEAT for heartbeat_timeout_s while the position stream is silent too. PX4 sends
    HEARTBEAT at 1 Hz: on a link losing 30% of its packets three in a row go missing in most
    flights, while the 30 Hz LOCAL_POSITION_NED shows the vehicle is there (its mode is then
    up to a few seconds old, which only delays noticing a pilot's takeover)."""
    return v is None or (v.heartbeat_age_s > m.heartbeat_timeout_s and v.position_age_s > TELEMETRY_SILENT_S)


def _hold_decision(state: MissionState, obs: Observation) -> Decision:
    """Ask for Hold; keep zero-velocity setpoints flowing until the vehicle shows it (so a
    switch that is slow to take effect never leaves OFFBOARD without setpoints). A disarmed
    vehicle has nothing to hold: nothing is sent."""
    v = obs.vehicle
    if v is not None and not v.armed:
        return Decision(setpoint=None)
    if v is not None and v.mode == FlightMode.OFFBOARD:
        return Decision(setpoint=Setpoint.hold_still(), request=Request.HOLD)
    return Decision(setpoint=None, request=Request.HOLD if v is not None and v.mode != FlightMode.HOLD and v.armed else None)


def step(state: MissionState, obs: Observation, m: MissionModel) -> tuple[MissionState, Decision]:
    """Advance the mission by one tick. Pure: same inputs, same outputs. A tick whose setpoint
    or kept reference would hold a NaN or an infinity (a corrupt observation, an overflow of an
    unsaturated law) aborts instead (``nonfinite``, naming it) and asks for Hold."""
    t = obs.t_s
    if state.start_s is None:
        state = replace(state, start_s=t, since_s=t)
    state = stall.begin(state, t)
    state, watched = _watch_carrier(state, obs, m)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # judged below, not warned about
        new, dec = _step(state, obs, m)
    if watched:
        dec = replace(dec, events=(*watched, *dec.events))
    bad = _nonfinite(new, dec)
    if bad is None:
        return replace(new, tick_s=t), dec
    aborted = _abort(state, t, AbortReason.NONFINITE, f"non-finite {bad} in {state.phase.value}")
    return replace(aborted, tick_s=t), _decided(aborted, obs, f"abort: non-finite {bad}: asking for Hold")


def _watch_carrier(state: MissionState, obs: Observation, m: MissionModel) -> tuple[MissionState, tuple[str, ...]]:
    """``state`` with ``carrier_fresh_s`` moved to now on a tick with a fresh carrier state
    (:func:`mission.phases.types.carrier_fresh`); before separation, the events of a carrier state
    going stale and of a fresh one again."""
    t, c = obs.t_s, obs.carrier
    fresh = carrier_fresh(obs, m)
    last, was_fresh = state.carrier_fresh_s, state.carrier_fresh_s is not None and state.carrier_fresh_s == state.tick_s
    if fresh:
        state = replace(state, carrier_fresh_s=t)
    if state.phase not in BEFORE_SEPARATION or state.phase is Phase.PREFLIGHT or last is None or state.tick_s is None:
        return state, ()
    if not fresh and was_fresh and c is not None and c.alive is not False:
        return state, (f"carrier state {describe_age(c)} (mission.carrier_timeout_s = {m.carrier_timeout_s:g}): riding "
                       f"the dock point predicted with its age, no separation on it; carrier_lost after "
                       f"{m.carrier_lost_s:g} s without a fresh one",)
    if fresh and not was_fresh:
        return state, (f"carrier state fresh again after {t - last:.2f} s",)
    return state, ()


def _carrier_lost(state: MissionState, obs: Observation, m: MissionModel) -> str | None:
    """Why the carrier counts as lost before separation (None: it does not): no state, its
    liveliness token gone, a stale state that is not trusted, or no fresh state for
    ``mission.carrier_lost_s`` (an older, trusted one is ridden meanwhile, predicted with its age)."""
    if carrier_fresh(obs, m):
        return None
    c = obs.carrier
    if c is None or c.alive is False or c.untrusted is not None or state.carrier_fresh_s is None:
        return _carrier_detail(obs, m)  # gone, or stale and not trusted (a forgery, not a stall): at once
    unfresh_s = obs.t_s - state.carrier_fresh_s
    if unfresh_s <= m.carrier_lost_s:
        return None
    return f"{_carrier_detail(obs, m)}; none fresh for {unfresh_s:.2f} s (mission.carrier_lost_s = {m.carrier_lost_s:g})"


def _step(state: MissionState, obs: Observation, m: MissionModel) -> tuple[MissionState, Decision]:
    """The failsafes, then (after a stall: :mod:`mission.phases.stall`) the reference restarted on
    the vehicle, then the phase's handler; the carrier's position (a fresh, trusted one) as the
    vehicle's home while flying."""
    t = obs.t_s
    state, early = _failsafes(state, obs, m)
    if early is not None:
        return state, early
    settling = stall.settling(state, t)
    state, resumed = stall.resume(state, obs)
    v = obs.vehicle
    if state.battery_start is None and v is not None and v.battery_pct is not None:
        state = replace(state, battery_start=(t, v.battery_pct))  # the drain rate counts from here
    leg_model = m.legs[state.leg] if m.legs else m  # the leg's target (scenario.targets)
    handler = HANDLERS[state.phase]
    state, decision = handler(state, obs, leg_model)
    if resumed:
        decision = replace(decision, events=(*resumed, *decision.events))
    if settling and state.phase.flying and not state.seated:
        decision = stall.by_velocity(decision)
    c = obs.carrier
    if c is not None and c.worst_age_s <= m.carrier_timeout_s and c.untrusted is None and state.phase.flying:
        decision = replace(decision, home_ned_m=c.position_ned_m + c.velocity_ned_m_s * c.age_s)
    return state, decision


_KEPT = ("x_ref", "u_ref", "e_ref", "u_cmd", "anchor", "integral")


def _nonfinite(state: MissionState, dec: Decision) -> str | None:
    """The first of the decision's setpoint parts (and home) and the state's kept vectors that is not finite."""
    sp = dec.setpoint
    if sp is not None:
        for name in ("velocity_ned_m_s", "position_ned_m", "acceleration_ned_m_s2"):
            v = getattr(sp, name)
            if v is not None and not np.isfinite(v).all():
                return f"setpoint {name} {np.asarray(v).tolist()}"
    if dec.home_ned_m is not None and not np.isfinite(dec.home_ned_m).all():
        return f"home_ned_m {np.asarray(dec.home_ned_m).tolist()}"
    for name in _KEPT:
        v = getattr(state, name)
        if v is not None and not np.isfinite(v).all():
            return f"{name} {np.asarray(v).tolist()}"
    return None


def _failsafes(state: MissionState, obs: Observation, m: MissionModel) -> tuple[MissionState, Decision | None]:
    """Transitions that any phase can take, checked before the phase's own logic."""
    t, v, ph = obs.t_s, obs.vehicle, state.phase
    if ph in (Phase.DONE,):
        return state, Decision(setpoint=None)
    if ph == Phase.ABORT:
        if _vehicle_lost(v, m):
            return state, Decision(setpoint=None)  # nobody to talk to: PX4's own failsafe acts
        if state.reason in _HANDS_OFF:
            return state, Decision(setpoint=None)
        return state, _hold_decision(state, obs)
    if obs.interrupted:
        new = _abort(state, t, AbortReason.INTERRUPTED, "signal")
        return new, _decided(new, obs, "abort: interrupted")
    if ph != Phase.PREFLIGHT and _vehicle_lost(v, m):
        new = _abort(state, t, AbortReason.VEHICLE_LOST, "no HEARTBEAT")
        return new, Decision(setpoint=None, events=("abort: vehicle heartbeat lost",))
    fault = _disarmed_in_flight(ph, v, state.seated)
    if fault:
        new = _abort(state, t, AbortReason.VEHICLE_DISARMED, fault)
        return new, Decision(setpoint=None, events=(f"abort: {fault}; streaming stopped",))
    state, disturbed = deck.watch(state, obs, m)
    if disturbed:
        new = _abort(state, t, AbortReason.DECK_DISTURBED, disturbed)
        return new, Decision(setpoint=None, events=(f"abort: {disturbed}; someone else flies it, not the mission",))
    if "identity" in obs.failed:
        new = _abort(state, t, AbortReason.VEHICLE_AMBIGUOUS, obs.failed["identity"])
        event = f"abort: {obs.failed['identity']}"
        return new, (Decision(setpoint=None, events=(event,)) if ph == Phase.PREFLIGHT else _decided(new, obs, event))
    final_modes = (FlightMode.HOLD, FlightMode.LAND)
    sitting = state.seated and ph not in deck.TAKING_OFF  # on the deck, not taking off: PX4's mode is not ours yet
    if ph in FLYING and not sitting and v is not None and v.mode != FlightMode.OFFBOARD \
            and not (ph in HANDING_OVER and v.mode in final_modes):
        reason = AbortReason.VEHICLE_FAILSAFE if v.in_failsafe else AbortReason.PILOT_OVERRIDE
        new = _abort(state, t, reason, f"vehicle switched to {v.mode}")
        return new, Decision(setpoint=None, events=(f"abort: vehicle left OFFBOARD ({v.mode}); not fighting it",))
    if ph not in (Phase.PREFLIGHT,) and v is not None and not v.position_valid:
        if TELEMETRY_SILENT_S < v.position_age_s <= m.heartbeat_timeout_s and stall.settling(state, t):
            return state, stall.unread(state, t)  # the link's thread stalled with the loop: not read yet
        if TELEMETRY_SILENT_S < v.position_age_s <= m.heartbeat_timeout_s:
            # The position stream went quiet (a link blackout, not an estimator failure): hover
            # until the heartbeat timeout decides whether the vehicle is lost.
            return state, Decision(setpoint=Setpoint.hold_still(), events=("telemetry silent",))
        new = _abort(state, t, AbortReason.POSITION_LOST, "position estimate invalid")
        return new, _decided(new, obs, "abort: position estimate lost")
    lost = _carrier_lost(state, obs, m) if ph in BEFORE_SEPARATION - {Phase.PREFLIGHT} else None
    if lost is not None:
        new = _abort(state, t, AbortReason.CARRIER_LOST, lost)
        return new, _decided(new, obs, "abort: carrier state lost before separation")
    if state.start_s is not None and t - state.start_s > m.max_duration_s and ph not in (Phase.HOLD, Phase.LAND):
        new = _abort(state, t, AbortReason.TIMEOUT, f"mission longer than {m.max_duration_s:g} s")
        return new, _decided(new, obs, "abort: mission timeout")
    return state, None


# Aborts after which nothing more is sent: the vehicle is gone, someone else has it (a pilot,
# PX4's own failsafe, whoever disarmed it), or nothing was ever sent (geometry).
_HANDS_OFF = frozenset({AbortReason.VEHICLE_LOST, AbortReason.PILOT_OVERRIDE, AbortReason.VEHICLE_FAILSAFE,
                        AbortReason.GEOMETRY, AbortReason.VEHICLE_DISARMED, AbortReason.DECK_DISTURBED})


def _disarmed_in_flight(ph: Phase, v: VehicleObs | None, seated: bool = False) -> str:
    """Why the vehicle is not where the phase needs it ("" if it is): disarmed in a phase that
    flies it (:data:`ARMED`), or landed by PX4's land detector (EXTENDED_SYS_STATE ON_GROUND;
    PX4 reports a disarmed multicopter as landed within about LNDMC_TRIG_TIME / 3) in a phase
    that needs it in the air (:data:`AIRBORNE`). ``seated`` (on the carrier's deck,
    mission.ride = "deck"): landed is where it is, and disarmed too, except while it takes off."""
    if v is None:
        return ""
    if seated:
        return f"vehicle disarmed while taking off from the deck in {ph.value} (HEARTBEAT)" \
            if ph in deck.TAKING_OFF and not v.armed else ""
    if ph in ARMED and not v.armed:
        return f"vehicle disarmed in {ph.value} (HEARTBEAT)"
    if ph in AIRBORNE and v.on_ground:
        return f"vehicle landed in {ph.value} (EXTENDED_SYS_STATE ON_GROUND)"
    return ""


def _decided(state: MissionState, obs: Observation, event: str) -> Decision:
    d = _hold_decision(state, obs)
    return replace(d, events=(event,))


def _carrier_detail(obs: Observation, m: MissionModel) -> str:
    c = obs.carrier
    if c is None:
        return "no carrier state received"
    if c.alive is False:
        return "carrier liveliness token gone"
    detail = f"carrier state {describe_age(c)} (limit {m.carrier_timeout_s:g} s)"
    return detail if c.untrusted is None else f"{detail}; not trusted: {c.untrusted}"


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
    ready = v is not None and v.heartbeat_age_s <= m.heartbeat_timeout_s and v.position_valid and carrier_fresh(obs, m)
    if not ready:
        if t - state.since_s > m.connect_timeout_s:
            if v is None:
                why, reason = "no vehicle", AbortReason.VEHICLE_LOST
            elif not carrier_fresh(obs, m):
                why, reason = "no carrier", AbortReason.CARRIER_LOST
            elif v.heartbeat_age_s > m.heartbeat_timeout_s:
                why, reason = "vehicle silent", AbortReason.VEHICLE_LOST
            else:  # heard, but its estimator has no local position yet
                why, reason = "no vehicle position", AbortReason.POSITION_LOST
            if v is None and "signing" in obs.failed:
                why, reason = obs.failed["signing"], AbortReason.SIGNING_MISMATCH
            new = _abort(state, t, reason, why)
            return new, Decision(setpoint=None, events=(f"abort: preflight: {why}",))
        return state, Decision(setpoint=None)
    assert v is not None  # ready
    dock = dock_point(obs, m)
    problem = live_geometry_problem(dock, v.position_ned_m, m)
    if problem is None:
        try:
            check_assumptions(dock, m.tick.target, m.tick.law, planar_carrier=m.tick.planar_carrier, field_prefix="mission")
        except AssumptionError as exc:
            problem = str(exc)
    if problem is not None:
        new = _abort(state, t, AbortReason.GEOMETRY, problem)
        return new, Decision(setpoint=None, events=(f"abort: geometry: {problem}",))
    new = enter(state, Phase.STREAMING, t)
    return new, Decision(setpoint=Setpoint.hold_still(), dock=dock, events=("preflight ok",))


def _streaming(state, obs, m):
    t = obs.t_s
    if m.deck is not None:  # riding on the deck: disarmed, nothing to stream yet (mission.phases.deck)
        if t - state.since_s >= m.prestream_s:
            return deck.seat(state, obs, m)
        return state, Decision(setpoint=None)
    if t - state.since_s >= m.prestream_s:
        nxt = Phase.OFFBOARD if obs.vehicle.armed else Phase.ARMING
        return enter(state, nxt, t), Decision(setpoint=Setpoint.hold_still(), request=Request.OFFBOARD if nxt == Phase.OFFBOARD else Request.ARM)
    return state, Decision(setpoint=Setpoint.hold_still())


def _arming(state, obs, m):
    t = obs.t_s
    if Request.ARM in obs.failed:
        new = _abort(state, t, AbortReason.ARMING_REFUSED, obs.failed[Request.ARM])
        return new, Decision(setpoint=None, events=(f"abort: arming refused: {obs.failed['arm']}",))
    if obs.vehicle.armed:
        return enter(state, Phase.OFFBOARD, t), Decision(setpoint=Setpoint.hold_still(), request=Request.OFFBOARD)
    return state, Decision(setpoint=Setpoint.hold_still(), request=Request.ARM)


def _offboard(state, obs, m):
    t, v = obs.t_s, obs.vehicle
    if Request.OFFBOARD in obs.failed:
        new = _abort(state, t, AbortReason.OFFBOARD_REFUSED, obs.failed[Request.OFFBOARD])
        return new, _decided(new, obs, f"abort: OFFBOARD refused: {obs.failed['offboard']}")
    if v.mode == FlightMode.OFFBOARD:
        new = enter(state, Phase.JOIN, t, x_ref=v.position_ned_m.copy(), u_cmd=ZERO.copy())
        return new, Decision(setpoint=Setpoint.hold_still())
    return state, Decision(setpoint=Setpoint.hold_still(), request=Request.OFFBOARD)

def _final(state, obs, m):
    return enter(state, Phase.DONE, obs.t_s), Decision(setpoint=None, events=("mission complete",))


#: Phases that hand the vehicle to PX4's Hold or Land: the vehicle may show those modes.
HANDING_OVER = frozenset({Phase.ARRIVED, Phase.HOME, Phase.FALLBACK})


def _navigating(state: MissionState, obs: Observation, m: MissionModel) -> tuple[MissionState, Decision]:
    """SEPARATED/NAVIGATING: the paper's navigation, unless the battery calls the passenger home."""
    if m.recovery is not None and state.phase is Phase.NAVIGATING:
        why = battery.battery_recall(state, obs, m)
        if why is not None:
            return recovery.begin(state, obs, m, why)
    return navigate(state, obs, m)


def _arrived(state: MissionState, obs: Observation, m: MissionModel) -> tuple[MissionState, Decision]:
    """ARRIVED: hand over to Hold or Land; with final_action "return", hold the target for the
    task (mission.at_target_s), or less if the battery says so, then come home."""
    if m.recovery is None:
        return arrived(state, obs, m)
    if obs.t_s - state.since_s >= m.recovery.at_target_s:
        return recovery.begin(state, obs, m, "task done")
    why = battery.battery_recall(state, obs, m)
    if why is not None:
        return recovery.begin(state, obs, m, why)
    new, dec = navigate(state, obs, m)
    return replace(new, phase=Phase.ARRIVED, since_s=state.since_s), dec


def finished(state: MissionState, decision: Decision) -> bool:
    """True when the controller loop may stop: DONE, or ABORT with nothing left to send."""
    if state.phase == Phase.DONE:
        return True
    return state.phase == Phase.ABORT and decision.setpoint is None and decision.request is None


HANDLERS = {
    Phase.PREFLIGHT: _preflight,
    Phase.STREAMING: _streaming,
    Phase.ARMING: _arming,
    Phase.OFFBOARD: _offboard,
    Phase.JOIN: join,
    Phase.RIDING: lambda state, obs, m: deck.ride(state, obs, m) if state.seated else riding(state, obs, m),
    Phase.SEPARATED: _navigating,
    Phase.NAVIGATING: _navigating,
    Phase.ARRIVED: _arrived,
    Phase.RETURNING: recovery.returning,
    Phase.HOLDOFF: recovery.holdoff,
    Phase.APPROACH: recovery.approach,
    Phase.GO_AROUND: recovery.go_around_phase,
    Phase.DOCKED: recovery.docked,
    Phase.HOME: recovery.home,
    Phase.TRANSIT: recovery.transit,
    Phase.FALLBACK: recovery.fallback_phase,
    Phase.HOLD: _final,
    Phase.LAND: _final,
}
