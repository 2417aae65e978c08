"""Riding on the carrier's deck (pure; ``mission.ride = "deck"``, docs/deck-riding.md).

The dock point is the deck. While the passenger sits on it (``MissionState.seated``) PX4 may show it
disarmed, landed (ON_GROUND) or out of OFFBOARD without that being a fault; the machine's
failsafes (:mod:`mission.phases.machine`) read ``seated``. ::

    STREAMING --prestream_s (nothing sent: the vehicle is disarmed)--> RIDING, seated
    RIDING, seated: carried, disarmed, nothing sent
        --the latch predicted within mission.arm_lead_s--> stream the deck's motion (full setpoints:
          the deck point, its velocity and acceleration), after prestream_s ARM, then OFFBOARD
          (PX4 auto-disarms a vehicle that has not taken off after COM_DISARM_PRFLT: it re-arms)
        --latch, armed in OFFBOARD--> SEPARATED, seated: the paper's law from e_pc = 0; the deck's
          keep-out in the safety filter (mission.core.safety.DeckKeepOut) lifts it off before it
          moves sideways --higher than mission.deck_clear_height_m above the deck--> seated ends
        --latch, not armed in OFFBOARD--> ABORT (arming_refused | offboard_refused)
    DOCKED (contact) --> seated: the reference presses DeckRide.press_m below the reported height
          (over the deck, no deeper than DeckRide.press_floor_m below its plane: :func:`landing`); once PX4's
          land detector says ON_GROUND, DISARM (PX4 refuses it before; on a deck faster than
          LNDMC_XY_VEL_MAX it never says so: the passenger stays armed, pressing, until the carrier
          slows) --> TRANSIT / HOME seated, then RIDING seated (the next leg) or DONE.

While seated and not taking off, the deck is watched (:func:`watch`): the vehicle armed after
it was seen disarmed (unless the mission streams to arm it), a mode other than the one it sat in
(or OFFBOARD, which the mission asks for when it arms), or the vehicle higher than
``mission.deck_clear_height_m`` above the deck is someone else flying it: ABORT (``deck_disturbed``), nothing more sent, the carrier
told (the status's reason) so it stops; that flight is never taken for a take-off.

Frames: local NED [m], [m/s]; times [s] on the controller's clock.
"""
from __future__ import annotations

from mission.core.records import replace
from typing import Any

import numpy as np

from mission.core.law import norm
from mission.core.tick import latch_point, passenger_tick, separation_due
from mission.core.setpoint import Setpoint
from mission.flight_mode import FlightMode
from mission.phases.flying import Tracked, _carrier_acceleration, _track, navigate
from mission.phases.phase import Phase, Request
from mission.phases.types import (
    ZERO,
    AbortReason,
    Decision,
    DeckRide,
    MissionModel,
    MissionState,
    Observation,
    carrier_fresh,
    dock_point,
    enter,
    my_turn,
)

#: Phases of the take-off: seated, the vehicle must be armed and in OFFBOARD.
TAKING_OFF = frozenset({Phase.SEPARATED, Phase.NAVIGATING})


def watch(state: MissionState, obs: Observation, m: MissionModel) -> tuple[MissionState, str]:
    """The deck watch (module docstring): the state (what it saw kept in ``deck_watch``) and why
    the seated vehicle was disturbed ("" if it was not). While the mission streams to arm it
    (``streaming_since_s``), armed and OFFBOARD are what it asked for."""
    v = obs.vehicle
    if not state.seated or state.phase in TAKING_OFF or v is None or m.deck is None:
        return (replace(state, deck_watch=None) if state.deck_watch is not None else state), ""
    asking = state.streaming_since_s is not None
    seen_disarmed, mode = state.deck_watch if state.deck_watch is not None else (False, v.mode)
    if not asking and seen_disarmed and v.armed:
        return state, f"armed on the deck without the mission asking (in {v.mode})"
    if v.mode != mode and not (asking and v.mode == FlightMode.OFFBOARD):
        return state, f"switched from {mode} to {v.mode} on the deck without the mission asking"
    if obs.carrier is not None:
        height = float(dock_point(obs, m)[2] - v.position_ned_m[2])
        if height > m.deck.clear_height_m:
            return state, f"{height:.2f} m above the deck without the mission asking"
    return replace(state, deck_watch=(not asking and (seen_disarmed or not v.armed), mode)), ""


def _kept(tr: Tracked) -> dict[str, Any]:
    """What the state keeps of a tick's tracking (typed for ``replace``)."""
    return dict(tr.kept())


def _deck(m: MissionModel) -> DeckRide:
    assert m.deck is not None  # only with mission.ride = "deck"
    return m.deck


def seconds_to_latch(obs: Observation, m: MissionModel) -> float:
    """When the latch will fire [s], at the carrier's present closing speed on the target (inf if
    it is not closing, or the carrier heads for another passenger's target: :func:`my_turn`)."""
    assert obs.carrier is not None
    if not my_turn(obs, m):
        return float("inf")
    e_tc = m.tick.target - dock_point(obs, m)
    dist = float(norm(e_tc))
    closing = float(np.dot(obs.carrier.velocity_ned_m_s, e_tc)) / max(dist, 1e-9)
    if closing <= 0.05:
        return float("inf")
    return max(dist - m.tick.event_distance_m, 0.0) / closing


def seat(state: MissionState, obs: Observation, m: MissionModel, events: tuple[str, ...] = ()) -> tuple[MissionState, Decision]:
    """STREAMING -> RIDING, seated: the reference on the deck, nothing sent."""
    dock = dock_point(obs, m)
    v_dock = np.asarray(obs.carrier.velocity_ned_m_s, dtype=float)  # type: ignore[union-attr]
    new = enter(state, Phase.RIDING, obs.t_s, seated=True, streaming_since_s=None, x_ref=dock.copy(), e_ref=ZERO.copy(),
                prev_dock=dock.copy(), u_ref=v_dock.copy(), u_cmd=v_dock.copy())
    return new, Decision(setpoint=None, dock=dock, events=(*events, "on the deck: riding the carrier"))


def ride(state: MissionState, obs: Observation, m: MissionModel) -> tuple[MissionState, Decision]:
    """RIDING while seated (see the module docstring)."""
    t, v, c = obs.t_s, obs.vehicle, obs.carrier
    assert v is not None and c is not None  # the failsafes checked both
    if c.untrusted is not None:
        # not a deck to arm or separate on: hold (the status says so: the carrier pauses), follow
        # the deck as the vehicle feels it if armed; the latch waits
        x_own = pressed(v.position_ned_m, m)
        events: tuple[str, ...] = () if state.held_dock is not None else (
            f"carrier feed not trusted ({c.untrusted}): holding on the deck",)
        held = replace(state, held_dock=dock_point(obs, m) if state.held_dock is None else state.held_dock)
        return _sit(held, obs, m, x_own, v.velocity_ned_m_s, events, may_disarm=state.streaming_since_s is None)
    state = replace(state, held_dock=None)
    dock = dock_point(obs, m)
    v_dock = np.asarray(c.velocity_ned_m_s, dtype=float)
    ready = v.armed and v.mode == FlightMode.OFFBOARD
    if separation_due(dock, False, m.tick) and state.prev_dock is not None and carrier_fresh(obs, m) and my_turn(obs, m):
        if not ready:
            reason = AbortReason.ARMING_REFUSED if not v.armed else AbortReason.OFFBOARD_REFUSED
            why = f"not {'armed' if not v.armed else 'in OFFBOARD'} on the deck when the separation came"
            new = enter(state, Phase.ABORT, t, reason=reason, detail=why)
            return new, Decision(setpoint=None, events=(f"abort: {why}",))
        theta, anchor = latch_point(state.prev_dock, dock, m.tick.target, m.tick)
        new = enter(state, Phase.SEPARATED, t, anchor=anchor, e_ref=ZERO.copy(), x_ref=anchor.copy(),
                    separation_time_s=t - (1 - float(theta)) * m.dt_s,
                    takeoff_offset=(takeoff_start(state, obs, m) - dock, ZERO.copy()), seated_sent=None)
        return navigate(new, obs, m, events=(f"separated at |e_tc| = {norm(m.tick.target - anchor):.3f} m: taking off "
                                              "from the deck",))
    due = seconds_to_latch(obs, m) <= _deck(m).arm_lead_s
    if state.streaming_since_s is None and not due:
        if v.armed:  # landed, not yet disarmed: press on the deck until PX4 lets it disarm
            return _sit(state, obs, m, landing(dock, obs, m), v_dock, (), prev_dock=dock)
        # the reference rides the deck; the command filter's last command is the deck's velocity,
        # the seated vehicle's own (what it reports adds its estimate's error: 0.2 m/s sigma, which
        # a stream starting from it would ramp out while disarmed), so the first setpoint streamed
        # is the deck's velocity (tracking's integral starts afresh)
        state = replace(state, x_ref=dock.copy(), e_ref=ZERO.copy(), prev_dock=dock.copy(), u_ref=v_dock.copy(),
                        u_cmd=v_dock.copy(), integral=None, accel_lp=None, seated_sent=None)
        return state, Decision(setpoint=None, dock=dock)
    events = ()
    since = state.streaming_since_s
    if since is None:
        since = t
        state = replace(state, streaming_since_s=t)
        events = ("separation due: streaming the deck's motion, then arming",)
    tick = passenger_tick(dock, v_dock, ZERO, False, m.tick, state.u_ref, m.dt_s)
    a_ref = _carrier_acceleration(obs, m) if m.tracking.kind == "full" else ZERO
    # the point tracked is where the passenger is by its estimate, moving with the deck (the law's
    # reference is the dock point): PX4 is asked for no pull towards a deck its estimate misplaces,
    # and the take-off starts from here (takeoff_start); the floor is left out under it (seated)
    tr = _track(state, obs, m, np.asarray(v.position_ned_m, dtype=float), tick.u, a_ref, standing=True)
    # before the latch: no take-off (armed or not as far as we know: PX4 arms before its HEARTBEAT says so)
    tr = replace(tr, setpoint=held_down(tr.setpoint, dock, obs, m))
    request = None
    if t - since >= m.prestream_s:
        request = Request.ARM if not v.armed else (Request.OFFBOARD if v.mode != FlightMode.OFFBOARD else None)
    failed = "arm" if "arm" in obs.failed else ("offboard" if "offboard" in obs.failed else None)
    if failed is not None:
        reason = AbortReason.ARMING_REFUSED if failed == "arm" else AbortReason.OFFBOARD_REFUSED
        new = enter(state, Phase.ABORT, t, reason=reason, detail=obs.failed[failed])
        return new, Decision(setpoint=None, events=(f"abort: {failed} refused on the deck: {obs.failed[failed]}",))
    sp = tr.setpoint
    sent = None if sp.position_ned_m is None else np.where(sp.position_axes, sp.position_ned_m, np.nan)  # NaN: not sent
    new = replace(state, x_ref=dock.copy(), e_ref=ZERO.copy(), prev_dock=dock.copy(), u_ref=tick.u,
                  seated_sent=sent, **_kept(tr))
    return new, tr.decision(request=request, dock=dock, P=float(tick.P), relative=tick.relative, desired=tick.desired,
                            safety_acted=tr.acted or bool(tick.safety.changed), events=events)


def takeoff_start(state: MissionState, obs: Observation, m: MissionModel) -> np.ndarray:
    """Where [m] NED the take-off's tracked point starts at the latch: the point whose setpoint
    continues the last one sent on the deck (``state.seated_sent``, held down ``press_m`` below
    the vehicle's reported height: tracking's position is ``x + lead (x - x_p) + bias``, solved
    for ``x``), else, velocity only sent (on that axis), where the passenger reports itself. Its offset from the
    deck (the dock point now; the anchor is where the law starts) relaxes to zero in flight (:func:`mission.phases.flying.navigate`), so neither the
    velocity nor the position sent jumps when the hold releases, however far the estimate puts
    the vehicle from the deck."""
    v = obs.vehicle
    assert v is not None  # riding: the failsafes checked it
    x_p = np.asarray(v.position_ned_m, dtype=float)
    if state.seated_sent is None:
        return x_p.copy()
    g = m.tracking
    sent = state.seated_sent
    if g.bias_compensation_s > 0 and v.velocity_bias_ned_m_s is not None:
        sent = sent - g.bias_compensation_s * np.asarray(v.velocity_bias_ned_m_s, dtype=float)
    # an axis sent velocity only (NaN) starts where the vehicle reports itself
    return np.where(np.isnan(sent), x_p, (sent + g.position_lead * x_p) / (1.0 + g.position_lead))


def _sit(state: MissionState, obs: Observation, m: MissionModel, x_ref: np.ndarray, u_ref: np.ndarray,
         events: tuple[str, ...], prev_dock: np.ndarray | None = None,
         may_disarm: bool = True) -> tuple[MissionState, Decision]:
    """Seated and armed, nothing due: press on the deck at ``x_ref`` [m] with ``u_ref`` [m/s]; ask
    PX4 to disarm once its land detector says landed (``may_disarm``: not while it waits, armed,
    for a take-off). Disarmed: nothing is sent. The dock recorded is what the feed says."""
    v = obs.vehicle
    assert v is not None
    if not v.armed:
        return replace(state, prev_dock=prev_dock if prev_dock is not None else state.prev_dock), Decision(
            setpoint=None, dock=dock_point(obs, m), events=events)
    dock = dock_point(obs, m)
    tr = _track(state, obs, m, x_ref, np.asarray(u_ref, dtype=float), ZERO, on_deck=over_deck(dock, obs, m))
    tr = replace(tr, setpoint=held_down(tr.setpoint, dock, obs, m))
    new = replace(state, x_ref=np.asarray(x_ref, dtype=float).copy(), u_ref=np.asarray(u_ref, dtype=float).copy(),
                  prev_dock=prev_dock if prev_dock is not None else state.prev_dock, **_kept(tr))
    return new, tr.decision(request=Request.DISARM if v.on_ground and may_disarm else None, dock=dock_point(obs, m),
                            safety_acted=tr.acted, events=events)


def pressed(dock: np.ndarray, m: MissionModel) -> np.ndarray:
    """Where the reference sits on the deck at ``dock`` [m] NED after a landing: ``press_m`` into it."""
    return dock + np.array([0.0, 0.0, _deck(m).press_m])


def held_down(sp: Setpoint, dock: np.ndarray, obs: Observation, m: MissionModel) -> Setpoint:
    """``sp`` asking the vehicle seated on the deck at ``dock`` [m] NED for no take-off: PX4's
    offboard ``want_takeoff`` lifts a landed vehicle on a position above its estimate, an upward
    velocity or an upward acceleration, so no vertical velocity or acceleration points up (NED:
    none negative) and the position is at least as low as :func:`landing`'s and ``press_m`` below
    the reported height, whatever the HEARTBEAT last said of arming and however low the estimate
    reads the vehicle: PX4 arms before its HEARTBEAT says so and at once reads the setpoint
    against its estimate, and a press into the deck's plane (a disarmed vehicle's :func:`landing`)
    or to the landing's floor over an estimate reading the vehicle lower is a position above the
    estimate, a take-off (measured: docs/deck-riding.md, "Landing on PX4's estimate")."""
    vel = sp.velocity_ned_m_s.copy()
    vel[2] = max(float(vel[2]), 0.0)
    pos, acc = sp.position_ned_m, sp.acceleration_ned_m_s2
    if pos is not None and acc is not None:
        pos, acc = pos.copy(), acc.copy()
        low = float(landing(dock, obs, m)[2])
        if obs.vehicle is not None:  # the estimate's: however low it reads the vehicle (the floor aside)
            low = max(low, float(obs.vehicle.position_ned_m[2]) + _deck(m).press_m)
        pos[2] = max(float(pos[2]), low)
        acc[2] = max(float(acc[2]), 0.0)
    return replace(sp, velocity_ned_m_s=vel, position_ned_m=pos, acceleration_ned_m_s2=acc)


def landing(dock: np.ndarray, obs: Observation, m: MissionModel) -> np.ndarray:
    """Where the reference sits on the deck at ``dock`` [m] NED after a contact. PX4 flies its
    estimate, whose height errs by decimetres, and its offboard take-off reads that estimate: a
    reference pressed below the deck's plane leaves the vehicle hovering over the deck when the
    estimate reads it low, and lifts it off again once landed when it reads it high. So, armed and
    reporting itself over the deck (within ``radius_m`` of the dock point horizontally), the
    reference is ``press_m`` below the height it reports (a steady push down until it touches, then
    held down), never deeper than ``press_floor_m`` below the deck's plane; horizontally on the
    dock point. Otherwise (disarmed, or off the deck by its report) :func:`pressed`."""
    d, v = _deck(m), obs.vehicle
    at = pressed(dock, m)
    if v is None or not v.armed or not over_deck(dock, obs, m):
        return at
    return np.array([at[0], at[1], min(float(v.position_ned_m[2]) + d.press_m, float(dock[2]) + d.press_floor_m)])


def over_deck(dock: np.ndarray, obs: Observation, m: MissionModel) -> bool:
    """Whether the vehicle reports itself over the deck at ``dock`` [m] NED: within the deck's
    ``radius_m`` of it horizontally (its height aside: the estimate's errs by decimetres)."""
    v = obs.vehicle
    return v is not None and float(np.hypot(*(v.position_ned_m[:2] - dock[:2]))) <= _deck(m).radius_m


def after_landing(obs: Observation, decision: Decision, dock: np.ndarray, m: MissionModel) -> Decision:
    """A seated phase's decision after a landing on the deck at ``dock`` [m] NED: nothing sent once
    PX4 disarmed; while armed the setpoint :func:`held_down` (never a climb), and DISARM asked (PX4
    accepts it only once its land detector says landed) while ON_GROUND."""
    v = obs.vehicle
    if v is None:
        return decision
    if not v.armed:
        return replace(decision, setpoint=None, request=None)
    if decision.setpoint is not None:
        decision = replace(decision, setpoint=held_down(decision.setpoint, dock, obs, m))
    if v.on_ground and decision.request is None:
        return replace(decision, request=Request.DISARM)
    return decision

