"""The phases that bring the passenger home (pure): RETURNING, HOLDOFF, APPROACH, GO_AROUND,
DOCKED, HOME and FALLBACK (``mission.final_action = "return"``).

::

    ARRIVED    --task done (mission.at_target_s), or the battery rule-----------------> RETURNING
    NAVIGATING --the battery rule (energy home + reserve > what is left)--------------> RETURNING
    RETURNING  --reference on the holdoff point, moving with the carrier--------------> HOLDOFF
    HOLDOFF    --vehicle within the settle radius of the holdoff point for the dwell, its
                 offset from it moving no more than settle speed x dwell (its positions),
                 the carrier at least recovery.settle_carrier_speed_m_s fast----------------> APPROACH
               (attempts used up: FALLBACK)
    APPROACH   --glide path flown, the contact conditions met (a deck: or landed on it)--> DOCKED
                 (on the descent it goes down only lined up, else holds its height)
               --outside the cone; carrier state late or not trusted; carrier accelerating or turning
                 beyond its limits; below the decision height not lined up; the descent longer
                 than its budget (descent_budget_s); the controller stalled (no tick for longer
                 than recovery.carrier_max_age_s)----------------------------------------------> GO_AROUND
    GO_AROUND  --climbed to the holdoff height------------------------------------------> HOLDOFF
    DOCKED     --contact held for the dwell--------------------------------------------> HOME
               --contact lost (beyond the dock tolerance, across or up: lost_dock)---------> GO_AROUND
    HOME       --the carrier has parked (slower than 0.1 m/s for the dwell)-------------> Hold -> HOLD
    any recovery phase --recovery.timeout_s, or no fresh carrier state for
                 recovery.carrier_lost_s---------------------------------------------------> FALLBACK
    FALLBACK   --at its point (off the carrier's path, or the landing point)------------> Hold | Land

Every reference here comes from :func:`mission.core.pursuit.pursue` (a goal chased with bounded
relative speed and acceleration) and then the reference-level safety filter, so no phase switch
makes the commanded velocity jump by more than ``recovery.accel_m_s2 * dt``. Geometry:
:mod:`mission.core.docking`. Frames: local NED [m], [m/s]; times [s] on the controller's clock.
"""
from __future__ import annotations

import math
from mission.core.records import replace

import numpy as np

from mission.core.docking import (cone_radius_m, contact, descent_progress, descent_step, gate_point, glide_point,
                                  heights_over_dock, holdoff_point, path_length_m, wait_for_vehicle)
from mission.core.law import norm
from mission.core.pursuit import PursuitLimits, pursue
from mission.core.safety import filter_velocity
from mission.flight_mode import FlightMode
from mission.phases import deck, queue, stall
from mission.phases.battery import next_leg_problem
from mission.phases.carrier_fitness import carrier_unfit, carrier_unsteady, mean_speed_m_s, observe_carrier
from mission.phases.flying import floor_over_the_ground, _track
from mission.phases.phase import Phase, Request
from mission.phases.types import (
    Decision,
    MissionModel,
    MissionState,
    Observation,
    RecoveryModel,
    RecoveryState,
    dock_point,
    enter,
    finish_leg,
)

PARKED_SPEED_M_S = 0.1  # [m/s] the carrier counts as parked below this
STILL_PARKED_SPEED_M_S = 0.2  # [m/s] HOME: a carrier counted parked stays so until its mean speed exceeds this
REFERENCE_AT_GOAL_M = 0.2  # [m] a reference this close to its goal has reached it
TRANSIT_REPORT_S = 15.0  # [s] TRANSIT names its wait for the carrier in an event this often


def _model(m: MissionModel) -> RecoveryModel:
    assert m.recovery is not None  # these phases exist only with final_action "return"
    return m.recovery


def begin(state: MissionState, obs: Observation, m: MissionModel, why: str) -> tuple[MissionState, Decision]:
    """Start the recovery (from NAVIGATING or ARRIVED): the reference goes on from where it is."""
    t = obs.t_s
    c = obs.carrier
    away = np.zeros(3)
    if c is not None:
        away = c.position_ned_m - m.tick.target
        away[2] = 0.0
    first = away / float(norm(away)) if float(norm(away)) > 1e-6 else np.array([1.0, 0.0, 0.0])
    if c is not None and c.yaw_rad is not None:
        first = np.array([math.cos(c.yaw_rad), math.sin(c.yaw_rad), 0.0])
    rec = RecoveryState(started_s=t, why=why, course=first, carrier_seen_s=t if c is not None else None)
    new = enter(state, Phase.RETURNING, t, recovery=rec, u_ref=state.u_ref if state.u_ref is not None else np.zeros(3))
    return returning(new, obs, m, events=(f"returning to the carrier ({why})",))


def _fly(state: MissionState, obs: Observation, m: MissionModel, goal_x: np.ndarray, goal_v: np.ndarray,
         limits: PursuitLimits, rec: RecoveryState | None, events: tuple[str, ...] = (),
         request: Request | None = None) -> tuple[MissionState, Decision]:
    """One tick towards a goal: pursue it, pass the reference through the reference's safety filter
    (obstacles, floor, the passenger's limits), track the reference; the state keeps ``rec``."""
    assert state.x_ref is not None and state.u_ref is not None
    _, u_next = pursue(state.x_ref, state.u_ref, goal_x, goal_v, limits, m.dt_s)
    keep_out = m.deck.keep_out(obs, m) if m.deck is not None else None
    cfg, neighbours = queue.apart(state, obs, m)
    # the reference's altitude floor over the ground as the passenger sees it, as the command's
    # ([relnav]: its own height estimate drifts by a metre or two, and a floor fixed in it lay
    # under the dock point: the reference sat on it, the descent never reached the dock)
    cfg = floor_over_the_ground(cfg, obs)
    # the rows phase in from the phase's start (as from the separation): they change with the phase
    # (none, the span, the separation), and a row in at once could correct the command in one tick
    safe = filter_velocity(state.x_ref, u_next, m.tick.obstacles, cfg, state.u_ref, m.dt_s, deck=keep_out,
                           neighbours=neighbours, since_separation_s=None if neighbours is None else obs.t_s - state.since_s)
    u_ref = np.asarray(safe.u, dtype=float)
    x_ref = state.x_ref + u_ref * m.dt_s
    a_ref = (u_ref - state.u_ref) / m.dt_s
    dock = dock_point(obs, m) if obs.carrier is not None else None
    # seated on the deck after a contact, over it by its report: the deck is its floor, the altitude
    # floor under it is left out (PX4's estimate reading the vehicle near or under it stopped the
    # press, and turned the setpoints velocity only: docs/deck-riding.md, "Landing under the floor")
    on_deck = state.seated and m.deck is not None and dock is not None and deck.over_deck(dock, obs, m)
    tr = _track(state, obs, m, x_ref, u_ref, a_ref, on_deck=on_deck)
    kept = tr.kept()
    new = replace(state, x_ref=x_ref, u_ref=u_ref, recovery=rec, u_cmd=kept["u_cmd"], integral=kept["integral"])
    return new, tr.decision(dock=dock, desired=u_ref, safety_acted=tr.acted or bool(safe.changed), events=events,
                            request=request)


def _give_up(state: MissionState, obs: Observation, m: MissionModel, rec: RecoveryState) -> str | None:
    """Why the recovery must fall back now (None: it goes on)."""
    r, t = _model(m), obs.t_s
    if t - rec.started_s > r.timeout_s:
        return f"not docked within recovery.timeout_s = {r.timeout_s:g} s"
    seen = rec.carrier_seen_s if rec.carrier_seen_s is not None else rec.started_s
    if obs.carrier is None or t - seen > r.carrier_lost_s:
        return f"no fresh carrier state for {t - seen:.1f} s"
    return None


def fallback(state: MissionState, obs: Observation, m: MissionModel, why: str,
             events: tuple[str, ...] = ()) -> tuple[MissionState, Decision]:
    """Enter FALLBACK: its goal is ``recovery.fallback_point_ned_m`` (land) or a point
    ``fallback_offset_m`` sideways off the carrier's path (hold), at ``fallback_height_m`` above the
    dock's height, pushed out of the target's keep-out."""
    r, t = _model(m), obs.t_s
    rec = state.recovery
    assert rec is not None and obs.vehicle is not None
    dock_z = (dock_point(obs, m)[2] if obs.carrier is not None else obs.vehicle.position_ned_m[2])
    if r.fallback == "land" and r.fallback_point_ned_m is not None:
        goal = np.array([r.fallback_point_ned_m[0], r.fallback_point_ned_m[1], dock_z - r.fallback_height_m])
    else:
        x_p = obs.vehicle.position_ned_m
        side = np.array([-rec.course[1], rec.course[0], 0.0])
        if obs.carrier is not None and float(np.dot(x_p - obs.carrier.position_ned_m, side)) < 0:
            side = -side
        goal = np.array([x_p[0], x_p[1], dock_z - r.fallback_height_m]) + r.fallback_offset_m * side
    off = goal - m.tick.target
    off[2] = 0.0
    if float(norm(off)) < r.keep_out_m:  # never inside the target's keep-out
        unit = off / float(norm(off)) if float(norm(off)) > 1e-6 else np.array([1.0, 0.0, 0.0])
        goal[:2] = m.tick.target[:2] + unit[:2] * r.keep_out_m
    rec = replace(rec, fallback_why=why, fallback_goal=goal)
    new = finish_leg(replace(state, recovery=rec), obs, f"fallback: {why}")
    new = enter(new, Phase.FALLBACK, t, legs_skipped="the recovery fell back" if m.next_target is not None else None)
    return fallback_phase(new, obs, m, events=(*events, f"recovery falls back: {why}"))


def fallback_phase(state, obs, m, events=()):
    """Fly to the fallback's point, then hand the vehicle to PX4's Hold or Land there."""
    r = _model(m)
    rec = state.recovery
    assert rec is not None and rec.fallback_goal is not None
    v = obs.vehicle
    want = Request.LAND if r.fallback == "land" else Request.HOLD
    mode = FlightMode.LAND if want is Request.LAND else FlightMode.HOLD
    if v.mode == mode:
        return enter(state, Phase.LAND if want is Request.LAND else Phase.HOLD, obs.t_s), Decision(
            setpoint=None, events=(*events, f"vehicle in {mode}"))
    there = float(norm(v.position_ned_m - rec.fallback_goal)) <= 0.5 and float(norm(v.velocity_ned_m_s)) <= 0.3
    return _fly(state, obs, m, rec.fallback_goal, np.zeros(3), r.returning, rec, events,
                request=want if there else None)


def returning(state, obs, m, events=()):
    """Chase the holdoff point (behind and above the dock point, moving with the carrier)."""
    r, t = _model(m), obs.t_s
    rec = observe_carrier(state.recovery, obs, r, t)
    why = _give_up(state, obs, m, rec)
    if why is not None:
        return fallback(replace(state, recovery=rec), obs, m, why, events)
    rec, waits, timed_out, queued = queue.turn(obs, m, rec)
    if timed_out is not None:
        return fallback(replace(state, recovery=rec), obs, m, timed_out, (*events, *queued))
    dock = dock_point(obs, m)
    h = queue.holdoff_goal(holdoff_point(dock, rec.course, r.geometry), rec, m, waits)
    v_c = obs.carrier.velocity_ned_m_s
    evs = (*events, *queued)
    if float(norm(state.x_ref - h)) <= REFERENCE_AT_GOAL_M and float(norm(state.u_ref - v_c)) <= r.settle_speed_m_s:
        state = enter(state, Phase.HOLDOFF, t)
        rec = replace(rec, settled_since_s=None)
        evs += ("at the holdoff point" if waits is None else "at the queue point",)
    return _fly(state, obs, m, h, v_c, r.returning, rec, evs)


def holdoff(state, obs, m, events=()):
    """Hold the holdoff point with the carrier's velocity until the vehicle has settled on it."""
    r, t = _model(m), obs.t_s
    rec = observe_carrier(state.recovery, obs, r, t)
    why = _give_up(state, obs, m, rec)
    if why is not None:
        return fallback(replace(state, recovery=rec), obs, m, why, events)
    rec, waits, timed_out, queued = queue.turn(obs, m, rec)
    if timed_out is not None:
        return fallback(replace(state, recovery=rec), obs, m, timed_out, (*events, *queued))
    dock = dock_point(obs, m)
    h = holdoff_point(dock, rec.course, r.geometry)
    v_c = obs.carrier.velocity_ned_m_s
    if waits is not None:  # not its turn: hold off at the queue point, no settling, no approach
        rec = replace(rec, settled_since_s=None, settled_offset_m=None)
        return _fly(state, obs, m, queue.holdoff_goal(h, rec, m, waits), v_c, r.returning, rec, (*events, *queued))
    events = (*events, *queued)
    offset = obs.vehicle.position_ned_m - h
    near = (float(norm(offset)) <= r.settle_radius_m
            and float(norm(v_c[:2])) >= r.settle_carrier_speed_m_s
            and carrier_unsteady(rec, obs, r) is None)
    refused = carrier_unfit(obs, r.carrier_max_age_s)
    c = obs.carrier
    if refused is not None and not (c.age_bound_s is None or c.worst_age_s > r.carrier_max_age_s):
        near = False  # not trusted, or its token gone: wait (an age beyond the approach's budget refuses one)
    evs = tuple(events)
    gates = m.relnav
    if gates is not None and not gates.acquired(obs.relative):  # search for the marker over the deck
        began = rec.search_since_s if rec.search_since_s is not None else t
        if t - began > gates.search_s:
            return fallback(replace(state, recovery=rec), obs, m, f"the marker not found over the deck within "
                            f"relnav.search_s = {gates.search_s:g} s", events)
        if rec.search_since_s is None:
            evs += ("searching for the marker over the deck",)
        rec = replace(rec, search_since_s=began, settled_since_s=None, settled_offset_m=None)
        h = h + r.geometry.holdoff_distance_m * rec.course  # over the gate, at the holdoff height
        return _fly(state, obs, m, h, v_c, r.returning, rec, evs)
    if gates is not None and rec.search_since_s is not None:
        rec = replace(rec, search_since_s=None)
        evs += ("marker acquired: back to the holdoff point",)
    near = near and (gates is None or gates.taken_in(obs.relative))
    rec, settled = _settled(rec, t, offset if near else None, r)
    if settled:
        # settled: an approach begins, or is refused (and counts) on a carrier state older than its budget
        if rec.attempts >= r.max_attempts:
            last = "" if refused is None else f"; the last refused: {refused}"
            return fallback(replace(state, recovery=rec), obs, m, f"{rec.attempts} approaches without docking{last}",
                            events)
        rec = replace(rec, attempts=rec.attempts + 1, s=0.0, descent=None, settled_since_s=None)
        if refused is not None:
            return _fly(state, obs, m, h, v_c, r.returning, rec, (*evs, f"approach {rec.attempts} refused: {refused}"))
        state = enter(state, Phase.APPROACH, t)
        evs += (f"approach {rec.attempts} begins",)
    return _fly(state, obs, m, h, v_c, r.returning, rec, evs)


def _settled(rec: RecoveryState, t: float, offset: np.ndarray | None, r: RecoveryModel) -> tuple[RecoveryState, bool]:
    """HOLDOFF's settle rule: the vehicle has kept within ``recovery.settle_radius_m`` of the
    holdoff point for ``recovery.settle_dwell_s`` (and at least one tick), and all that time its
    offset from the point (``offset`` [m] NED, None: not near) stayed within
    ``recovery.settle_speed_m_s`` times the dwell of where it was at the start: it moved with the
    carrier, as its positions tell. Not from its velocity: PX4's velocity estimate errs by
    ~0.25 m/s for seconds (docs/px4-hold.md), and holding a position PX4 flies that error as an
    offset, steady, while the velocity it reports keeps the whole error. An offset that strays
    further starts the dwell again from there. The recovery state with the dwell's start
    (``settled_since_s``, ``settled_offset_m``), and whether the vehicle has settled."""
    if offset is None:
        return replace(rec, settled_since_s=None, settled_offset_m=None), False
    since, start = rec.settled_since_s, rec.settled_offset_m
    if since is None or start is None:
        return replace(rec, settled_since_s=t, settled_offset_m=offset.copy()), False
    span = t - since
    if float(norm(offset - start)) > r.settle_speed_m_s * max(r.settle_dwell_s, span):
        return replace(rec, settled_since_s=t, settled_offset_m=offset.copy()), False
    return rec, span >= r.settle_dwell_s and span > 0.0


def go_around(state, obs, m, why: str, events=()):
    """Enter GO_AROUND: climb to the holdoff height where the vehicle is (relative to the dock
    point), then back to the holdoff point."""
    r = _model(m)
    rec = state.recovery
    assert rec is not None
    dock = dock_point(obs, m)
    rel = obs.vehicle.position_ned_m - dock
    climb = np.array([rel[0], rel[1], -r.geometry.holdoff_height_m])
    rec = replace(rec, climb_to=climb, settled_since_s=None, descent=None, marker_lost_s=None, descent_since_s=None)
    new = enter(state, Phase.GO_AROUND, obs.t_s, recovery=rec, seated=False)
    v_c = obs.carrier.velocity_ned_m_s if obs.carrier is not None else np.zeros(3)
    return _fly(new, obs, m, dock + climb, v_c, r.returning, rec, (*events, f"go-around: {why}"))


def go_around_phase(state, obs, m, events=()):
    r, t = _model(m), obs.t_s
    rec = observe_carrier(state.recovery, obs, r, t)
    why = _give_up(state, obs, m, rec)
    if why is not None:
        return fallback(replace(state, recovery=rec), obs, m, why, events)
    dock = dock_point(obs, m)
    v_c = obs.carrier.velocity_ned_m_s
    assert rec.climb_to is not None
    goal = dock + rec.climb_to
    if float(norm(state.x_ref - goal)) <= REFERENCE_AT_GOAL_M:
        return holdoff(enter(state, Phase.HOLDOFF, t, recovery=replace(rec, climb_to=None)), obs, m,
                       events=(*events, "climbed: back to the holdoff point"))
    return _fly(state, obs, m, goal, v_c, r.returning, rec, events)


def approach(state, obs, m, events=()):
    """Fly the glide path onto the gate with the carrier's motion fed forward, wait there until the
    vehicle is lined up over the dock point, then descend vertically onto it."""
    r, t = _model(m), obs.t_s
    rec = observe_carrier(state.recovery, obs, r, t)
    why = _give_up(state, obs, m, rec)
    if why is not None:
        return fallback(replace(state, recovery=rec), obs, m, why, events)
    state = replace(state, recovery=rec)
    if stall.settling(state, t) and state.last_stall is not None and state.last_stall[1] > r.carrier_max_age_s:
        # unwatched for longer than a carrier state may be old on the approach: a new one, from the holdoff point
        return go_around(state, obs, m, f"no tick for {state.last_stall[1]:.2f} s (the controller stalled; "
                         f"recovery.carrier_max_age_s = {r.carrier_max_age_s:g})", events)
    why = carrier_unfit(obs, r.carrier_max_age_s)
    if why is not None:
        return go_around(state, obs, m, why, events)
    unsteady = carrier_unsteady(rec, obs, r)
    if unsteady is not None:
        return go_around(state, obs, m, unsteady, events)
    q = m.queue
    if q is not None and rec.descent is None:  # a neighbour docking, or one approaching that goes first
        own = queue.claim(t - rec.started_s, None if obs.vehicle is None else obs.vehicle.battery_pct, q.must_pct,
                          q.rank)
        gives_way = queue.yield_reason(own, obs.neighbours, q.must_pct)
        if gives_way is not None:
            return go_around(state, obs, m, f"gives way: {gives_way}", events)
    g = r.geometry
    dock = dock_point(obs, m)
    gate = gate_point(dock, g)
    v_c = obs.carrier.velocity_ned_m_s
    v = obs.vehicle
    here = contact(v.position_ned_m, v.velocity_ned_m_s, dock, v_c)
    if rec.descent is None:  # on the glide path, or waiting at the gate
        ref_point = glide_point(dock, rec.course, rec.s, g)
        off = float(norm(v.position_ned_m - ref_point))
        if off > cone_radius_m(ref_point, dock, g):
            return go_around(state, obs, m, f"{off:.2f} m off the glide path "
                             f"(cone {cone_radius_m(ref_point, dock, g):.2f} m)", events)
        length = path_length_m(g)
        s = min(1.0, rec.s + r.approach.speed_m_s * m.dt_s / length)
        goal = glide_point(dock, rec.course, s, g)
        along = (gate - holdoff_point(dock, rec.course, g)) / length
        goal_v = v_c + (along * r.approach.speed_m_s if s < 1.0 else 0.0)
        rec = replace(rec, s=s)
        if s >= 1.0:
            at_gate = rec.settled_since_s if rec.settled_since_s is not None else t
            rec = replace(rec, settled_since_s=at_gate)
            lined_up = here.horizontally_within(g) and float(norm(state.x_ref - gate)) <= REFERENCE_AT_GOAL_M
            blocked = None if m.relnav is None else m.relnav.descent_blocked(obs.relative)
            if lined_up and blocked is not None and t - at_gate > r.gate_timeout_s:
                return go_around(state, obs, m, f"no descent below the decision height: {blocked} "
                                 f"for {r.gate_timeout_s:g} s at the gate", events)
            if lined_up and blocked is None:
                rec = replace(rec, descent=0.0, settled_since_s=None, descent_since_s=t)
                events = (*events, "lined up over the deck: descending")
            elif t - at_gate > r.gate_timeout_s:
                return go_around(state, obs, m, f"not lined up over the deck within {r.gate_timeout_s:g} s "
                                 f"({here.horizontal_error_m:.2f} m, {here.horizontal_relative_speed_m_s:.2f} m/s)", events)
        return _fly(state, obs, m, goal, goal_v, r.approach, rec, events)
    # On the descent the vehicle goes down only while lined up; out of line it holds its height
    # over the dock point, at least three contact heights over the deck (so the deck is never
    # met outside the contact conditions), and goes around
    # once it is off the deck, or out of line for gate_timeout_s. A relative speed that swings
    # over the limit for a moment (PX4: two velocity estimates, a rover's speed loop) pauses it.
    # On a deck PX4's land detector saying landed, over the deck by the estimate, is the contact:
    # the estimate errs by decimetres, so a vehicle on the deck may read itself above it, out of line
    landed = m.deck is not None and v.on_ground and here.horizontal_error_m <= r.deck_radius_m \
        and here.horizontal_relative_speed_m_s <= g.contact_max_horizontal_speed_m_s
    budget = descent_budget_s(m)
    if not here.within(g) and not landed and rec.descent_since_s is not None and t - rec.descent_since_s > budget:
        # out of line or searching, back in line for a moment, out again: each pause's own timer
        # restarts, so without a bound on the whole a descent could hover over the deck for minutes
        return go_around(state, obs, m, f"the descent did not reach the deck within {budget:g} s "
                         f"({here.horizontal_error_m:.2f} m, {here.horizontal_relative_speed_m_s:.2f} m/s)", events)
    # The marker lost or the estimate unsure below the decision height: climb back to the gate (a
    # search), go around after search_s; a vehicle already meeting the contact conditions docks
    # below. Blind, the relative height drifts with the vehicle's own height estimate (the marker
    # no longer pins the deck in its frame; PX4 holds its estimate, so the vehicle truly sinks or
    # rises with its error: 0.65 m in 1.5 s, 0.15-0.28 m within 0.5 s of the loss measured), so
    # the search climbs rather than hold a height it no longer knows, at once
    # (relnav.descent_marker_timeout_s, not the gate's marker_timeout_s) and ahead of the
    # out-of-line hold below (whose horizontal error is the drifted estimate's)
    blocked = None if m.relnav is None else m.relnav.descent_blocked(obs.relative, below=True)
    if blocked is not None and not here.within(g) and not landed:
        lost = rec.marker_lost_s if rec.marker_lost_s is not None else t
        if t - lost > m.relnav.search_s:
            return go_around(state, obs, m, f"on the descent: {blocked} (relnav.search_s = {m.relnav.search_s:g})",
                             events)
        # the out-of-line pause's timer restarts: the climb is its own pause (search_s, the budget),
        # and carried over it sent a vehicle out of line for a moment after the climb round at once
        rec = replace(rec, marker_lost_s=lost, descent=0.0, settled_since_s=None)
        return _fly(state, obs, m, gate, v_c, r.approach, rec, events)
    if not here.horizontally_within(g) and not landed:
        out_since = rec.settled_since_s if rec.settled_since_s is not None else t
        if here.horizontal_error_m > r.deck_radius_m or t - out_since > r.gate_timeout_s:
            return go_around(state, obs, m, f"off the deck on the descent ({here.horizontal_error_m:.2f} m, "
                             f"{here.horizontal_relative_speed_m_s:.2f} m/s)", events)
        # held no lower than three contact heights over the deck, so it does not sit on it (PX4
        # dips 0.1 m below a descending reference)
        held = max(0.0, min(rec.descent, heights_over_dock(3.0, g)))
        rec = replace(rec, settled_since_s=out_since, descent=held)
        return _fly(state, obs, m, gate + held * (dock - gate), v_c, r.approach, rec, events)
    if rec.marker_lost_s is not None:
        # the marker back after a climb: the descent goes on from where the reference has climbed
        # to, not from the gate (with 10 % of the time blind, a descent restarted from the gate
        # at each loss spent its budget), but no lower than three contact heights: the marker's
        # correction of the drifted estimate (0.1-0.2 m) is still being let through
        # (relnav.correction_rate_m_s), and a descent resumed under them met the contact band
        # out of the contact conditions (scenarios 15, 16: 0.54-0.61 m/s)
        rec = replace(rec, descent=min(descent_progress(state.x_ref, dock, g), heights_over_dock(3.0, g)))
    rec = replace(rec, settled_since_s=None, marker_lost_s=None)
    descent, rate, x_ref = wait_for_vehicle(*descent_step(rec.descent, here.horizontal_error_m, g, r.descent_speed_m_s,
                                                          r.final_descent_speed_m_s, r.final_lineup_margin, m.dt_s),
                                            state.x_ref, v.position_ned_m, dock, g, r.final_descent_lag_m)
    state = replace(state, x_ref=x_ref)
    goal = gate + descent * (dock - gate)
    goal_v = v_c + ((dock - gate) / g.decision_height_m * rate if descent < 1.0 else 0.0)
    rec = replace(rec, descent=descent)
    if here.within(g) or landed:  # on the deck under the contact conditions (ahead of its reference: at once)
        figures = {"horizontal_error_m": round(here.horizontal_error_m, 4),
                   "height_error_m": round(here.height_error_m, 4),
                   "horizontal_relative_speed_m_s": round(here.horizontal_relative_speed_m_s, 4),
                   "vertical_relative_speed_m_s": round(here.vertical_relative_speed_m_s, 4),
                   "attempts": rec.attempts, "time_s": round(t, 4), "battery_pct": v.battery_pct}
        rec = replace(rec, contact=figures, settled_since_s=t)
        state = enter(state, Phase.DOCKED, t, seated=m.deck is not None)  # on a deck: it lands on it
        events = (*events, f"contact: {here.horizontal_error_m:.3f} m, {here.horizontal_relative_speed_m_s:.2f} m/s")
    return _fly(state, obs, m, goal, goal_v, r.approach, rec, events)


def docked(state, obs, m, events=()):
    """On the dock point with the carrier's velocity: after the dwell, the passenger is home."""
    r, t = _model(m), obs.t_s
    rec = observe_carrier(state.recovery, obs, r, t)
    dock = dock_point(obs, m)
    v_c = obs.carrier.velocity_ned_m_s
    lost = lost_dock(state, obs, m, dock)
    if lost is not None:
        return go_around(replace(state, recovery=rec), obs, m, f"lost the dock after contact: {lost}", events)
    if not state.seated:  # holding contact on the carrier's word: as fresh as on the approach
        unfit = carrier_unfit(obs, r.carrier_max_age_s)
        if unfit is not None:
            return go_around(replace(state, recovery=rec), obs, m, unfit, events)
    if obs.carrier.untrusted is not None:  # a resync or a contested source: not a dock to stay on
        return go_around(replace(state, recovery=rec), obs, m, f"carrier feed not trusted ({obs.carrier.untrusted})",
                         events)
    evs = tuple(events)
    if rec.settled_since_s is not None and t - rec.settled_since_s >= r.docked_dwell_s:
        outcome = "done" if rec.why == "task done" else f"docked after a recall: {rec.why}"
        state = finish_leg(replace(state, recovery=rec), obs, outcome)
        skip = None if m.next_target is None else next_leg_problem(state, obs, m)
        if m.next_target is None or skip is not None:
            state = replace(state, legs_skipped=skip)
            rec = replace(rec, settled_since_s=None)
            state = enter(state, Phase.HOME, t)
            evs += ("docked: riding home" if skip is None else f"docked: riding home; the next leg is skipped ({skip})",)
            return _on_dock(state, obs, m, dock, v_c, rec, evs)
        return begin_next_leg(state, obs, m, events=(*evs, "docked: on to the next target"))
    return _on_dock(state, obs, m, dock, v_c, rec, evs)


def descent_budget_s(m: MissionModel) -> float:
    """[s] the longest one descent from the gate may take before it goes around: twice the
    descent's own time (``decision_height_m / descent_speed_m_s``), twice the pause out of line
    it allows (``gate_timeout_s``) and, with ``[relnav]``, the search for a lost marker
    (``relnav.search_s``)."""
    r = _model(m)
    g = r.geometry
    return 2.0 * g.decision_height_m / r.descent_speed_m_s + 2.0 * r.gate_timeout_s + (
        m.relnav.search_s if m.relnav is not None else 0.0)


def lost_dock(state: MissionState, obs: Observation, m: MissionModel, dock: np.ndarray) -> str | None:
    """Why the vehicle has left the dock point ``dock`` [m] NED after its contact (None: it has
    not), horizontally and vertically apart: farther than ``mission.dock_tolerance_m`` across;
    higher or lower than that, except, seated on a deck, lower (pressed, its estimate's height
    errs by decimetres; :func:`mission.phases.deck.landing` bounds it) or higher while PX4's land
    detector says landed."""
    v = obs.vehicle
    assert v is not None  # the failsafes checked it
    off = v.position_ned_m - dock
    across, above = float(np.hypot(off[0], off[1])), -float(off[2])
    tol = m.dock_tolerance_m
    if across > tol:
        return f"{across:.2f} m from the dock point across (mission.dock_tolerance_m = {tol:g})"
    if state.seated and (above <= tol or v.on_ground):
        return None
    if abs(above) > tol:
        return f"{above:+.2f} m above the dock point (mission.dock_tolerance_m = {tol:g})"
    return None


def _on_dock(state: MissionState, obs: Observation, m: MissionModel, dock: np.ndarray, v_c: np.ndarray,
             rec: RecoveryState | None, events: tuple[str, ...] = (), request: Request | None = None
             ) -> tuple[MissionState, Decision]:
    """One tick on the dock point with the carrier's velocity; seated on a deck (mission.ride =
    "deck"), pressed into it and disarmed once PX4 has seen it land (:mod:`mission.phases.deck`)."""
    if not state.seated:
        return _fly(state, obs, m, dock, v_c, _model(m).approach, rec, events, request=request)
    confirmed = _confirm_contact(rec, obs)
    if rec is not None and confirmed is not None and confirmed is not rec and state.legs_done \
            and state.legs_done[-1]["contact"] is rec.contact:
        # landed after the leg was done (the dwell counts from the contact): its record says so too
        state = replace(state, legs_done=(*state.legs_done[:-1], {**state.legs_done[-1], "contact": confirmed.contact}))
    rec = confirmed
    new, dec = _fly(state, obs, m, deck.landing(dock, obs, m), v_c, _model(m).approach, rec, events, request=request)
    return new, deck.after_landing(obs, dec, dock, m)


def _confirm_contact(rec: RecoveryState | None, obs: Observation) -> RecoveryState | None:
    """``rec`` with its contact confirmed (``confirmed_s``, ``confirmed_by``) the first tick the
    passenger itself reports it has landed (PX4's land detector: EXTENDED_SYS_STATE ON_GROUND),
    seated on the deck after a contact: what the passenger can check of its dock, not the
    carrier's claimed position."""
    if rec is None or rec.contact is None or "confirmed_s" in rec.contact or obs.vehicle is None \
            or not obs.vehicle.on_ground:
        return rec
    return replace(rec, contact={**rec.contact, "confirmed_s": round(obs.t_s, 4),
                                 "confirmed_by": "landed on the deck (EXTENDED_SYS_STATE ON_GROUND)"})


def home(state, obs, m, events=()):
    """Ride the dock point while the carrier parks; once it has parked and the vehicle sits on the
    dock point again (the contact conditions) for the dwell, hand the vehicle to PX4's Hold."""
    r, t = _model(m), obs.t_s
    v = obs.vehicle
    if v.mode == FlightMode.HOLD:
        return enter(state, Phase.HOLD, t), Decision(setpoint=None, events=(*events, "vehicle in Hold above the carrier"))
    rec = observe_carrier(state.recovery, obs, r, t)
    if obs.carrier is None:
        return _fly(state, obs, m, state.x_ref, np.zeros(3), r.approach, rec, events, request=Request.HOLD)
    dock = dock_point(obs, m)
    v_c = obs.carrier.velocity_ned_m_s
    on_it = contact(v.position_ned_m, v.velocity_ned_m_s, dock, v_c)
    # parked by the mean of the window's velocities, with hysteresis: on a parked carrier a GNSS
    # velocity's noise reads 0.1 m/s and more on half the ticks, and each of those restarted the dwell
    limit = PARKED_SPEED_M_S if rec.settled_since_s is None else STILL_PARKED_SPEED_M_S
    parked = mean_speed_m_s(rec.carrier_samples, v_c) <= limit and (on_it.within(r.geometry) or state.seated) \
        and obs.carrier.untrusted is None
    since = (rec.settled_since_s if rec.settled_since_s is not None else t) if parked else None
    rec = replace(rec, settled_since_s=since)
    done = since is not None and t - since >= r.docked_dwell_s
    if state.seated:  # on the deck: home once the carrier has parked and PX4 has disarmed the passenger
        if parked and not v.armed:
            return enter(state, Phase.DONE, t, recovery=rec), Decision(setpoint=None, events=(
                *events, "disarmed on the parked carrier's deck", "mission complete"))
        return _on_dock(state, obs, m, dock, v_c, rec, events)
    return _fly(state, obs, m, dock, v_c, r.approach, rec, events, request=Request.HOLD if done else None)


def begin_next_leg(state: MissionState, obs: Observation, m: MissionModel,
                   events: tuple[str, ...] = ()) -> tuple[MissionState, Decision]:
    """After a dock: the next target's leg begins, riding the dock point; TRANSIT first while the
    carrier is nearer to that target than ``mission.leg_start_margin_m`` beyond b c."""
    assert obs.carrier is not None and state.recovery is not None  # docked just now
    new = enter(state, Phase.TRANSIT, obs.t_s, leg=state.leg + 1, anchor=None, separation_time_s=None,
                arrival_window=(), e_ref=np.zeros(3), prev_dock=None, legs_skipped=None)
    return _on_dock(new, obs, m, dock_point(obs, m), obs.carrier.velocity_ned_m_s,
                    replace(state.recovery, settled_since_s=None), events)


def transit(state, obs, m, events=()):
    """Ride the dock point (a leg after the first) until the carrier stands far enough from the
    leg's target for the paper's Assumption 1 (b c + ``mission.leg_start_margin_m``, and slower
    than 0.1 m/s: the law starts from rest), then RIDING: the reference sits on the dock point
    again and the law takes over. Every ``TRANSIT_REPORT_S`` of waiting an event names the wait
    (two frames that disagree can make it last until ``mission.max_duration_s``)."""
    r, t = _model(m), obs.t_s
    dock = dock_point(obs, m)
    v_c = obs.carrier.velocity_ned_m_s
    rest = deck.landing(dock, obs, m) if state.seated else dock
    if (float(norm(m.tick.target - dock)) >= m.leg_start_m and float(norm(v_c[:2])) <= PARKED_SPEED_M_S
            and float(norm(state.x_ref - rest)) <= 0.05):
        if state.seated:  # on the deck: the next leg rides it (mission.phases.deck.ride)
            new, dec = deck.ride(enter(state, Phase.RIDING, t, x_ref=rest.copy(), prev_dock=dock.copy(),
                                       e_ref=np.zeros(3), streaming_since_s=None, recovery=None), obs, m)
            return new, replace(dec, events=(*events, f"leg {state.leg + 1}: riding on the deck", *dec.events))
        new = enter(state, Phase.RIDING, t, x_ref=dock.copy(), prev_dock=dock.copy())
        return _fly(new, obs, m, dock, v_c, r.approach, None, (*events, f"leg {state.leg + 1}: riding"))
    waited = (t - state.since_s, max((state.tick_s if state.tick_s is not None else t) - state.since_s, 0.0))
    if math.floor(waited[0] / TRANSIT_REPORT_S) > math.floor(waited[1] / TRANSIT_REPORT_S):
        events = (*events, f"leg {state.leg + 1}: waited {waited[0]:.0f} s for the carrier: the dock point is "
                  f"{float(norm(m.tick.target - dock)):.2f} m from the target (the leg starts at {m.leg_start_m:.2f} m, "
                  f"b c + mission.leg_start_margin_m), the carrier at {float(norm(v_c[:2])):.2f} m/s "
                  f"(at most {PARKED_SPEED_M_S:g})")
    return _on_dock(state, obs, m, dock, v_c, state.recovery, events)
