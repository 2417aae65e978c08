"""The phases that fly the reference (pure): JOIN, RIDING, SEPARATED/NAVIGATING and ARRIVED.

The reference is the paper's closed loop (:mod:`mission.core.tick`) integrated in error coordinates
about the dock point; the vehicle tracks it (:mod:`mission.core.tracking`) through the safety filter.
Each handler takes ``(state, obs, model)`` and returns ``(state, decision)``; the vehicle and,
before separation, the carrier have been checked by :func:`mission.phases.step`'s failsafes.

Frames: local NED [m], [m/s]; times [s] on the controller's clock.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mission.core.records import replace
from mission.flight_mode import FlightMode
from mission.core import arrival
from mission.core.law import norm
from mission.core.pursuit import PursuitLimits, pursue
from mission.core.setpoint import Setpoint
from mission.phases.types import ZERO, Decision, MissionModel, MissionState, Observation, Phase, carrier_fresh, dock_point, enter, my_turn
from mission.phases.phase import Request
from mission.core.safety import SafetyConfig, filter_velocity
from mission.core.tick import DEPARTURE_THRESHOLD_M, TickModel, carrier_tick, latch_point, passenger_tick, separation_due
from mission.core.tracking import AXIS_CHANGED_M_S, lead_acceleration, progress, setpoint as tracking_setpoint, update_integral, velocity_demand


@dataclass(frozen=True)
class Tracked:
    """One tick of tracking: the setpoint to send, whether the safety filter changed its
    velocity, and what the state keeps (the integral, the lead's low-passed acceleration)."""

    setpoint: Setpoint
    acted: bool
    integral: np.ndarray
    accel_lp: np.ndarray

    def decision(self, **kw) -> Decision:
        return Decision(setpoint=self.setpoint, **kw)

    def kept(self) -> dict[str, np.ndarray]:
        """What the state keeps: the velocity sent [m/s] (the filter's previous command), the
        integral and the lead's low-passed acceleration."""
        return {"u_cmd": self.setpoint.velocity_ned_m_s, "integral": self.integral, "accel_lp": self.accel_lp}


#: the phases whose tracking damps with ``mission.near_deck_damping_per_s``: the deck's approach, where the
#: loop closes on the marker (GO_AROUND climbs away from it)
NEAR_DECK_DAMPED = frozenset({Phase.HOLDOFF, Phase.APPROACH})

#: [m] the most the altitude floor follows the ground the relative estimate puts under the
#: passenger: two GNSS frames disagree by 1-3 m (docs/relnav.md)
FLOOR_GROUND_SHIFT_MAX_M = 3.0


def floor_over_the_ground(limits: SafetyConfig, obs: Observation) -> SafetyConfig:
    """The command's limits with the altitude floor (``z_max_m`` [m] NED, the ground at 0) over
    the ground the carrier drives on as the passenger sees it, when the relative estimator gives
    the carrier in the passenger's own frame (``[relnav]``): the carrier's estimated height,
    at most :data:`FLOOR_GROUND_SHIFT_MAX_M` either way. The passenger's own estimate drifts
    vertically (measured: 1 m off while riding, seed 1 of the relnav demo), and a floor fixed in
    it then lay at the hover point: its barrier turned the riding setpoints velocity-only for
    0.9 s as the carrier pulled away (docs/relnav.md, "Riding on late fixes")."""
    c = obs.carrier
    if obs.relative is None or c is None or limits.z_max_m is None or len(c.position_ned_m) != 3:
        return limits
    ground = float(np.clip(c.position_ned_m[2], -FLOOR_GROUND_SHIFT_MAX_M, FLOOR_GROUND_SHIFT_MAX_M))
    return replace(limits, z_max_m=limits.z_max_m + ground)


def tick_over_the_ground(m: MissionModel, obs: Observation, riding: bool = False) -> TickModel:
    """``m.tick`` with the passenger's altitude floor (the riding law's reference filter) over the
    ground as the passenger sees it (:func:`floor_over_the_ground`), as the command's and the
    recovery reference's are. Fixed in its frame, with its own height estimate 2 m off (the relnav
    Monte-Carlo's scenario 63) the dock point lay 1.1-1.5 m under it, and the barrier asked the
    riding reference 1.0-1.5 m/s up for seconds: the vehicle rose 0.6 m off the dock point (P1
    failed; docs/relnav.md, "The climb at once and the riding floor"). The same after the separation
    (navigate), so that the reference does not jump at the switch. ``riding``: with the riding
    limits (``m.riding_safety``, when set)."""
    own = m.riding_safety if riding and m.riding_safety is not None else m.tick.passenger_safety
    limits = floor_over_the_ground(own, obs)
    return m.tick if limits is m.tick.passenger_safety else replace(m.tick, passenger_safety=limits)


def _track(state: MissionState, obs: Observation, m: MissionModel, x_ref: np.ndarray, u_ref: np.ndarray,
           a_ref: np.ndarray, standing: bool = False, on_deck: bool = False, riding: bool = False) -> Tracked:
    """The setpoint that makes the vehicle follow the reference (:func:`mission.core.tracking.setpoint`):
    the velocity demand filtered at the vehicle's real position (obstacles, floor, speed and
    acceleration of the vehicle), full or velocity only as tracking decides it. The altitude floor
    (``z_max_m``) is left out for a vehicle ``standing`` under it, taking off (JOIN from the ground;
    seated, the take-off from the deck), while it reads itself under the floor; and ``on_deck``:
    seated on the deck after a contact (its landing, pressed into it) and over it by its report,
    where the deck, above the floor, is its floor. PX4's estimate of its height errs by decimetres:
    a floor 0.2 m under the deck stopped the landing's press and turned its setpoints velocity only
    (docs/deck-riding.md, "Landing under the floor"). ``riding``: the command's riding limits
    (``m.riding_command_safety``, when set). In :data:`NEAR_DECK_DAMPED` the damping is
    ``m.near_deck_damping_per_s`` when set."""
    v = obs.vehicle
    assert v is not None  # tracking happens only with a vehicle
    x_p = v.position_ned_m
    g = m.tracking
    if m.near_deck_damping_per_s is not None and state.phase in NEAR_DECK_DAMPED:
        g = replace(g, damping_per_s=m.near_deck_damping_per_s)
    integral = state.integral if state.integral is not None else np.zeros(3)
    desired = velocity_demand(x_ref, u_ref, x_p, integral, g)
    prev = state.u_cmd if state.u_cmd is not None else v.velocity_ned_m_s
    limits = floor_over_the_ground(m.riding_command_safety if riding and m.riding_command_safety is not None
                                   else m.command_safety, obs)
    if limits.z_max_m is not None and (on_deck or (standing and len(x_p) == 3 and x_p[2] > limits.z_max_m)):
        limits = replace(limits, z_max_m=None)
    safe = filter_velocity(x_p, desired, m.tick.obstacles, limits, prev, m.dt_s)
    acted = bool(safe.changed)
    a_sent, accel_lp = lead_acceleration(a_ref, state.accel_lp, g, m.dt_s)
    axes_changed = np.abs(safe.u - desired) > AXIS_CHANGED_M_S if acted else False  # per axis: the others keep tracking
    sp = tracking_setpoint(x_ref, u_ref, a_sent, x_p, safe.u, integral, g, v.velocity_ned_m_s, filtered=axes_changed,
                           velocity_bias=v.velocity_bias_ned_m_s)
    if not acted or g.kind == "velocity":
        integral = update_integral(integral, x_ref, x_p, g, m.dt_s)
    return Tracked(sp, acted, integral, accel_lp)


def _carrier_tick_model(obs: Observation, m: MissionModel) -> TickModel:
    """The law the carrier follows as this passenger predicts it: its leg's (``m.tick``) when it
    is its turn (:func:`mission.phases.types.my_turn`), else the same towards the target the
    carrier announces (``obs.carrier_target_ned_m``: it serves another passenger of the team,
    ``u_c = k_c e_tc`` towards that one's target). Predicted towards its own target instead, a
    rider carried along for a later target fed forward an acceleration of up to 1 m/s^2 the
    carrier never made, and lagged its dock point (docs/team.md, "The team's Monte-Carlo")."""
    aim = obs.carrier_target_ned_m
    if aim is None or my_turn(obs, m):
        return m.tick
    target = np.asarray(m.tick.target, dtype=float)
    return replace(m.tick, target=np.asarray(aim, dtype=float)[:target.shape[-1]])


def _docked_law_distance(obs: Observation, m: MissionModel, dock: np.ndarray) -> np.ndarray | None:
    """``|e_tc|`` [m] the riding law uses at the dock point ``dock`` [m]: None (its own, the
    distance to its target) on its turn; else at least ``b c``, so that the law stays on the
    docked branch (``P >= 0``: ``u_p = u_c``). Not its turn, the carrier may carry it within
    ``b c`` of its target on the way to another's (it must not latch there, and it does not),
    and the law's separating branch there, ``P e_pt`` (up to the speed limit, 3 m/s, towards its
    target), was the reference's velocity of a passenger still riding: it lagged its dock
    point by over the dock tolerance (P1 failed; docs/team.md, "The team's Monte-Carlo")."""
    if my_turn(obs, m):
        return None
    return np.asarray(max(float(norm(m.tick.target - dock)), m.tick.law.separation_distance_m))


def _carrier_acceleration(obs: Observation, m: MissionModel) -> np.ndarray:
    """The docked carrier's acceleration [m/s^2] NED: the one it measured and sent, if it sent
    one (a real vehicle does not follow its law exactly: a PX4 rover sticks, then leaps off);
    else as its law asks it, run where the carrier itself says it is (``CarrierObs.law_position_ned_m``:
    its own frame, or the passenger's when it runs there): the change of the carrier's command (``mission.core.tick.carrier_tick``,
    with its speed and acceleration limits) over one carrier step from the sample's state, or
    over ``mission.carrier_accel_horizon_s`` when that is longer. Analytic in the sample (no
    differences of samples): ``a_max`` along the command while the carrier speeds up, 0 at its
    speed limit, ``-k_c v_c`` on the final approach. Over one step an estimated velocity's noise
    (0.1-0.2 m/s) is a full ``a_max`` either way, flipping with the noise; over the horizon it is
    that noise over the horizon (docs/relnav.md, "Riding on late fixes"). A sent one is
    capped at the passenger's own ``max_accel_m_s2`` (a feed-forward, not an order). With none sent
    and the relative estimate's (``relnav.carrier_accel_tau_s`` > 0: the rate of the deck's estimated
    velocity), that one, horizontal for a planar carrier: the SIH rover cruises at its own speed,
    under the law's limit, and stands ~2 s before it moves off, where the law's prediction had the
    riding passenger 0.3-0.45 m ahead of the deck (docs/relnav.md, "Where the PX4 ride lost 0.3 m")."""
    a = _measured_acceleration(obs, m)
    return _law_acceleration(obs, m) if a is None else _capped(a, m)


def _capped(a: np.ndarray, m: MissionModel) -> np.ndarray:
    """A measured acceleration [m/s^2] capped at the passenger's own ``max_accel_m_s2`` (its riding
    command's, when set: the carrier's is fed forward to a passenger it carries)."""
    cap = (m.riding_command_safety or m.command_safety).max_accel_m_s2
    size = float(norm(a))
    return a * (cap / size) if cap is not None and size > cap else a


def _law_acceleration(obs: Observation, m: MissionModel) -> np.ndarray:
    """The carrier's acceleration [m/s^2] NED as its law asks it (:func:`_carrier_acceleration`)."""
    c = obs.carrier
    assert c is not None  # riding: the carrier was checked
    h = m.carrier_dt_s
    horizon = max(m.carrier_accel_horizon_s, h)
    nxt = carrier_tick(c.law_position_ned_m + c.velocity_ned_m_s * h, False, _carrier_tick_model(obs, m),
                       u_prev=c.velocity_ned_m_s, dt_s=horizon)
    return (np.asarray(nxt.u, dtype=float) - c.velocity_ned_m_s) / horizon


def _measured_acceleration(obs: Observation, m: MissionModel) -> np.ndarray | None:
    """The carrier's acceleration [m/s^2] NED as measured, not as its law predicts it: the one it
    sent, else the relative estimate's (``obs.relative``), that one's vertical zero for a planar
    carrier (the passenger's own height estimate drifts, the ground does not); None when neither
    gives one."""
    c = obs.carrier
    if c is not None and c.acceleration_ned_m_s2 is not None:
        return np.asarray(c.acceleration_ned_m_s2, dtype=float)
    rel = obs.relative
    if rel is None or rel.carrier_accel_ned_m_s2 is None:
        return None
    a = np.array(rel.carrier_accel_ned_m_s2, dtype=float)
    if m.tick.planar_carrier and len(a) == 3:
        a[2] = 0.0
    return a


def _ridden_dock(obs: Observation, m: MissionModel, fresh: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The dock point [m] and its velocity [m/s] NED now, and the carrier's acceleration
    [m/s^2] fed forward (:func:`_carrier_acceleration`; zero for a stale state, whose prediction
    has none). A fresh sample is moved on over its age ``T`` as the carrier moves: with the
    acceleration it sent (or the estimate's), ``v + a T``; else as its law asks it, one carrier step of length ``T``
    from the sample's velocity (:func:`mission.core.tick.carrier_tick`: its speed limit, and at
    most ``safety.carrier_max_accel_m_s2 * T`` of change). The dock point moves on by the mean of
    the two velocities. A GNSS fix 0.2-0.3 s old, the carrier starting at 1 m/s^2, would
    otherwise feed forward a velocity 0.2-0.3 m/s behind the carrier's, which the vehicle's
    position loop makes up only with an offset behind the dock (docs/relnav.md, "Riding on late
    fixes")."""
    c = obs.carrier
    assert c is not None  # riding: the carrier was checked
    dock, v = dock_point(obs, m), np.asarray(c.velocity_ned_m_s, dtype=float)
    if not fresh:
        return dock, v, ZERO
    measured = _measured_acceleration(obs, m)
    a = _law_acceleration(obs, m) if measured is None else _capped(measured, m)  # _carrier_acceleration's
    age = min(max(float(c.age_s), 0.0), m.carrier_timeout_s)
    if age <= 0.0:
        return dock, v, a
    if measured is not None:  # not the law's: the sample moves on with it
        v_now = v + a * age
    else:
        x_now = np.asarray(c.law_position_ned_m, dtype=float) + v * age  # where the carrier's law runs
        v_now = np.asarray(carrier_tick(x_now, False, _carrier_tick_model(obs, m), u_prev=v, dt_s=age).u, dtype=float)
    if m.tick.planar_carrier and len(v_now) == 3:
        v_now[2] = v[2]  # a ground carrier: its vertical velocity is the sample's (the estimate's noise), not led
    return dock + 0.5 * (v_now - v) * age, v_now, a


def _hold(state: MissionState, obs: Observation, m: MissionModel) -> tuple[MissionState, Decision]:
    """The carrier feed is not trusted (``obs.carrier.untrusted``: just bound, a resync after a
    jump, a contested source): the reference holds still where it is (riding: the dock point it
    had), nothing is fed forward and the latch cannot fire; ``held_dock`` says so (the carrier
    pauses: the status says ``holding``). What the feed says is still recorded as the dock."""
    assert obs.carrier is not None and obs.carrier.untrusted is not None and state.x_ref is not None
    held = state.x_ref.copy()
    events = () if state.held_dock is not None else (
        f"carrier feed not trusted ({obs.carrier.untrusted}): holding on the dock point it had",)
    tr = _track(state, obs, m, held, ZERO, ZERO)
    new = replace(state, x_ref=held, u_ref=ZERO.copy(), settled_since_s=None,
                  held_dock=held if state.held_dock is None else state.held_dock,
                  u_cmd=tr.setpoint.velocity_ned_m_s, integral=tr.integral)
    return new, tr.decision(dock=dock_point(obs, m), desired=ZERO, safety_acted=tr.acted, events=events)


def _toward_dock(x_ref: np.ndarray, dock: np.ndarray, v_dock: np.ndarray, m: MissionModel) -> tuple[np.ndarray, np.ndarray, bool]:
    """One tick of the reference towards the dock point at join speed (plus the dock's own
    velocity): (x_ref [m], u_ref [m/s], whether it is on the dock now)."""
    gap = dock - x_ref
    dist = float(norm(gap))
    if dist <= m.join_speed_m_s * m.dt_s:
        return dock.copy(), v_dock.copy(), True
    u_ref = gap / dist * m.join_speed_m_s + v_dock
    return x_ref + u_ref * m.dt_s, u_ref, False


def join(state, obs, m):
    """Move the reference from where the vehicle took over to the dock point at join speed."""
    t = obs.t_s
    if obs.carrier.untrusted is not None:
        return _hold(state, obs, m)
    state = replace(state, held_dock=None)  # trusted (again): joining goes on from where the reference is
    dock = dock_point(obs, m)
    v_dock = obs.carrier.velocity_ned_m_s
    x_ref, u_ref, on_dock = _toward_dock(state.x_ref, dock, v_dock, m)
    # Taking off from the ground, under the altitude floor: the floor's barrier would replace the
    # climb by its own approach to the floor (a climb rate that falls with the distance to it,
    # sent as velocity only: the filter wins over the reference), and a vehicle that leaves the
    # ground after the reference has climbed would hover under the floor (measured on PX4:
    # docs/recovery.md, "On real PX4"). The reference, which climbs to the dock point above the
    # floor, leads the vehicle up instead.
    tr = _track(state, obs, m, x_ref, u_ref, ZERO, standing=True)
    # Docked once the vehicle has settled on the dock point (within join_settle_m for
    # join_settle_s): the carrier starts its approach then, so what is left of the climb (its
    # overshoot) is not counted as riding offset; rest is judged on positions, not on the velocity
    # estimate (why, measured on PX4: docs/flying-px4.md, "JOIN waits until settled"). With the
    # relative estimate, only on a dock point that has taken in the estimate's jumps (as an approach
    # waits: RelnavGates.taken_in): the first markers move the deck by the seat's error, and a ride
    # begun while that was still being let through began 0.6-0.94 m off the deck (docs/team.md).
    v = obs.vehicle
    near = (on_dock and norm(v.position_ned_m - dock) <= m.join_settle_m
            and (m.relnav is None or obs.relative is None or m.relnav.taken_in(obs.relative)))
    settled = (state.settled_since_s if state.settled_since_s is not None else t) if near else None
    if settled is not None and t - settled >= m.join_settle_s:
        new = enter(state, Phase.RIDING, t, x_ref=dock.copy(), e_ref=ZERO.copy(), prev_dock=dock.copy(), u_ref=v_dock.copy(),
                    held_dock=None, **tr.kept())
        return new, tr.decision(dock=dock, desired=u_ref, safety_acted=tr.acted, events=("docked: riding the carrier",))
    return (replace(state, x_ref=x_ref, u_ref=u_ref, settled_since_s=settled, **tr.kept()),
            tr.decision(dock=dock, desired=u_ref, safety_acted=tr.acted))


def riding(state, obs, m):
    """Equilibrium (i): the reference stays exactly on the dock; the latch fires at b c - margin,
    on a trusted, fresh carrier state only. An untrusted one holds the reference on the dock point it
    had (:func:`_hold`); once the feed is trusted again the reference goes back to the dock
    point at join speed, and only then rides (and may latch) again. A stale one (older than
    mission.carrier_timeout_s: a stalled carrier) is ridden as the dock point predicted with its
    age (the carrier's last velocity fed forward, no acceleration: the prediction has none),
    the reference chasing it and, once a fresh state is back, the fresh dock point
    (:func:`_chase`) until it is on it again; the latch waits for a fresh one (the machine
    aborts after mission.carrier_lost_s without)."""
    t = obs.t_s
    if obs.carrier.untrusted is not None:
        return _hold(state, obs, m)
    fresh = carrier_fresh(obs, m)
    dock, v_dock, a_dock = _ridden_dock(obs, m, fresh)
    if state.held_dock is not None:
        x_ref, u_ref, on_dock = _toward_dock(state.x_ref, dock, v_dock, m)
        if not on_dock:
            tr = _track(state, obs, m, x_ref, u_ref, ZERO)
            return (replace(state, x_ref=x_ref, u_ref=u_ref, **tr.kept()),
                    tr.decision(dock=dock, desired=u_ref, safety_acted=tr.acted))
        state = replace(state, held_dock=None, prev_dock=dock.copy())
        event: tuple[str, ...] = ("carrier feed trusted again: back on the dock point, riding",)
    else:
        event = ()
    if state.chasing_dock or not fresh:
        chased = _chase(state, obs, m, dock, v_dock, fresh, event)
        if chased is not None:
            return chased
        state, event = replace(state, chasing_dock=False), (*event, "back on the dock point after a stale carrier state")
    if separation_due(dock, False, m.tick) and fresh and my_turn(obs, m):
        theta, anchor = latch_point(state.prev_dock, dock, m.tick.target, m.tick)
        new = enter(state, Phase.SEPARATED, t, anchor=anchor, e_ref=ZERO.copy(), x_ref=anchor.copy(),
                  separation_time_s=t - (1 - float(theta)) * m.dt_s)
        return navigate(new, obs, m, events=(f"separated at |e_tc| = {norm(m.tick.target - anchor):.3f} m",))
    tick = passenger_tick(dock, v_dock, ZERO, False, tick_over_the_ground(m, obs, riding=True), state.u_ref, m.dt_s,
                          e_tc_norm_m=_docked_law_distance(obs, m, dock))
    # velocity setpoints carry no acceleration; a stale state's prediction has none
    a_ref = a_dock if m.tracking.kind == "full" else ZERO
    tr = _track(state, obs, m, dock, tick.u, a_ref, riding=True)
    acted = tr.acted
    new = replace(state, x_ref=dock.copy(), e_ref=ZERO.copy(), prev_dock=dock.copy(), u_ref=tick.u, **tr.kept())
    return new, tr.decision(dock=dock, P=float(tick.P), relative=tick.relative, desired=tick.desired,
                         safety_acted=acted or bool(tick.safety.changed), events=event)


#: [m] riding, the reference that chases the dock point (:func:`_chase`) is back on it within
#: this of it (and within one tick's acceleration of its velocity): what is left is dropped
CHASE_DONE_M = 0.01


def _chase(state: MissionState, obs: Observation, m: MissionModel, dock: np.ndarray, v_dock: np.ndarray, fresh: bool,
           events: tuple[str, ...]) -> tuple[MissionState, Decision] | None:
    """RIDING with the reference chasing the dock point instead of sitting on it: while the
    carrier's state is stale, the dock point predicted with its age; once a fresh one is back,
    the fresh dock point, which lies elsewhere when the carrier did not drive on as predicted (it
    braked or turned in the gap: 1 m/s^2 of braking over a 1.5 s gap puts it 1.1 m behind the
    prediction and 1.5 m/s slower). The reference pursues it (:func:`mission.core.pursuit.pursue`,
    ``m.dock_chase``: the dock's velocity fed forward, at most mission.dock_rejoin_speed_m_s
    relative to it, its velocity changing at most at the passenger's acceleration limit), so
    neither its position nor its velocity jumps, where sitting on the fresh dock point would
    have jumped by the prediction's error. None once it is back on a fresh dock point (within
    :data:`CHASE_DONE_M` and one tick's acceleration): the caller rides on it. A latch due meanwhile
    fires (at b c, on the fresh state) with the reference's offset from the dock as the law's
    start (``e_ref``): no jump there either."""
    assert state.x_ref is not None and state.prev_dock is not None  # riding: both set on entering it
    u_prev = state.u_ref if state.u_ref is not None else v_dock
    # from the last tick's reference towards the dock point as it was then (its velocity back over
    # the tick): the reference lands on the dock point now, not a tick behind it
    x_ref, u_ref = pursue(state.x_ref, u_prev, dock - v_dock * m.dt_s, v_dock, m.dock_chase, m.dt_s)
    if fresh and norm(dock - x_ref) <= CHASE_DONE_M and norm(v_dock - u_ref) <= m.dock_chase.accel_m_s2 * m.dt_s:
        return None
    t = obs.t_s
    if fresh and separation_due(dock, False, m.tick) and my_turn(obs, m):
        theta, anchor = latch_point(state.prev_dock, dock, m.tick.target, m.tick)
        offset = x_ref - dock
        new = enter(state, Phase.SEPARATED, t, anchor=anchor, e_ref=offset, x_ref=anchor + offset, chasing_dock=False,
                    separation_time_s=t - (1 - float(theta)) * m.dt_s)
        return navigate(new, obs, m, events=(*events, f"separated at |e_tc| = {norm(m.tick.target - anchor):.3f} m"))
    tick = passenger_tick(dock, v_dock, ZERO, False, tick_over_the_ground(m, obs), u_prev, m.dt_s,  # the law's view
                          e_tc_norm_m=_docked_law_distance(obs, m, dock))
    a_ref = (u_ref - u_prev) / m.dt_s if m.tracking.kind == "full" else ZERO
    tr = _track(state, obs, m, x_ref, u_ref, a_ref)
    new = replace(state, x_ref=x_ref, u_ref=u_ref, e_ref=ZERO.copy(), prev_dock=dock.copy(), chasing_dock=True,
                  u_cmd=tr.setpoint.velocity_ned_m_s, integral=tr.integral, accel_lp=tr.accel_lp)
    return new, tr.decision(dock=dock, P=float(tick.P), relative=tick.relative, desired=u_ref, safety_acted=tr.acted,
                            events=events)


def _lag_m(state: MissionState, obs: Observation) -> float:
    """How far [m] the vehicle is behind the point it tracks (the reference, plus the take-off's
    offset) along the reference's direction of motion (0 when it is level or ahead, or the
    reference is still)."""
    if state.x_ref is None or state.u_ref is None or obs.vehicle is None:
        return 0.0
    speed = float(norm(state.u_ref))
    if speed < 1e-6:
        return 0.0
    tracked = state.x_ref if state.takeoff_offset is None else state.x_ref + state.takeoff_offset[0]
    return max(0.0, float(np.dot(tracked - obs.vehicle.position_ned_m, state.u_ref)) / speed)


#: The take-off's offset relaxes to zero at most this fast [m/s] and accelerating at most this
#: much [m/s^2] (pull 1/s near zero): on top of the law's own departure at the passenger's
#: acceleration limit (2 m/s^2 in cycle.toml: 0.04 m/s per tick at 50 Hz) it adds at most 0.006
#: m/s per tick, so the take-off's command stays within 0.05 m/s per tick; a 0.5 m offset (the
#: estimate's vertical error, 0.3 m RMS) is gone in about 2.5 s, while the vehicle climbs clear.
TAKEOFF_RELAX = PursuitLimits(speed_m_s=0.3, accel_m_s2=0.3, gain_per_s=1.0)


def _relax(offset: tuple[np.ndarray, np.ndarray] | None, m: MissionModel) -> tuple[np.ndarray, np.ndarray] | None:
    """The take-off's offset (offset [m], rate [m/s]) one tick on: pursued to zero within
    :data:`TAKEOFF_RELAX`, so the tracked point's velocity never jumps; None once it is there
    (within :data:`CHASE_DONE_M`, at rest within a tick's acceleration) or there was none."""
    if offset is None:
        return None
    delta, rate = pursue(offset[0], offset[1], ZERO, ZERO, TAKEOFF_RELAX, m.dt_s)
    if norm(delta) <= CHASE_DONE_M and norm(rate) <= TAKEOFF_RELAX.accel_m_s2 * m.dt_s:
        return None
    return delta, rate


def navigate(state, obs, m, events=()):
    """Equilibria (ii)->(iii): integrate the reference with the latched anchor, track it. Taking
    off from the deck, the point tracked is the reference plus the take-off's offset
    (``state.takeoff_offset``: where the passenger was by its estimate when the latch fired,
    relaxing to zero at bounded acceleration, :func:`_relax`), and the altitude floor is left out
    while the vehicle reads itself under it (as JOIN's): a seated vehicle whose estimate reads it
    below the deck would otherwise be sent the floor's climb at once. The reference keeps apart
    from the other passengers the observation holds (``obs.neighbours``, the separation barrier),
    its rows phasing in from the separation (``state.separation_time_s``)."""
    t = obs.t_s
    deck = m.deck.keep_out(obs, m) if m.deck is not None else None
    separated_for = None if state.separation_time_s is None else t - state.separation_time_s
    tick = passenger_tick(state.anchor, ZERO, state.e_ref, True, tick_over_the_ground(m, obs), state.u_ref, m.dt_s, deck=deck,
                          neighbours=obs.neighbours, since_separation_s=separated_for)
    # The reference advances at the rate the vehicle can follow (mission.core.tracking.progress); its
    # acceleration is its own velocity's change over the tick (a signal we generate: no noise).
    rate = progress(_lag_m(state, obs), m.tracking)
    u_ref = tick.u * rate
    e_ref = state.e_ref + u_ref * m.dt_s
    x_ref = state.anchor + e_ref
    u_prev = state.u_ref if state.u_ref is not None else u_ref
    a_ref = (u_ref - u_prev) / m.dt_s
    offset = _relax(state.takeoff_offset, m)
    if offset is None:
        tr = _track(state, obs, m, x_ref, u_ref, a_ref, standing=state.seated)
    else:
        a_off = (offset[1] - state.takeoff_offset[1]) / m.dt_s  # type: ignore[index]
        tr = _track(state, obs, m, x_ref + offset[0], u_ref + offset[1], a_ref + a_off, standing=state.seated)
    acted = tr.acted
    phase, since, window = state.phase, state.since_s, state.arrival_window
    evs = list(events)
    if phase == Phase.SEPARATED and norm(e_ref) > DEPARTURE_THRESHOLD_M:
        phase, since = Phase.NAVIGATING, t
        evs.append("left the carrier: navigating")
    seated = state.seated
    if seated and m.deck is not None and state.anchor is not None \
            and float(state.anchor[2] - obs.vehicle.position_ned_m[2]) > m.deck.clear_height_m:
        seated = False
        evs.append("cleared the deck")
    # Arrived: within the arrival radius for the dwell, and (if set) the positions of that window
    # moving slower than arrival_max_speed_m_s: judged on positions, not on the velocity estimate
    # (mission.core.arrival; a vehicle handed to Hold while still moving brakes past the radius).
    if phase == Phase.NAVIGATING:
        x_p = obs.vehicle.position_ned_m
        window = arrival.extend(window, t, x_p, bool(norm(x_p - m.tick.target) <= m.arrival_radius_m), m.arrival_dwell_s)
        if arrival.arrived(window, t, m.arrival_dwell_s, m.arrival_max_speed_m_s, m.dt_s):
            phase, since = Phase.ARRIVED, t
            evs.append("arrived at the target")
    new = replace(state, phase=phase, since_s=since, e_ref=e_ref, x_ref=x_ref, u_ref=u_ref, arrival_window=window,
                  seated=seated, takeoff_offset=offset, **tr.kept())
    dec = tr.decision(dock=dock_point(obs, m) if obs.carrier is not None else None, P=float(tick.P),
                   relative=tick.relative, desired=tick.desired, safety_acted=acted or bool(tick.safety.changed), events=tuple(evs))
    if phase == Phase.ARRIVED and m.recovery is None:
        dec = replace(dec, request=Request(m.final_action))
    return new, dec


def arrived(state, obs, m):
    t, v = obs.t_s, obs.vehicle
    want = FlightMode.HOLD if m.final_action == Request.HOLD else FlightMode.LAND
    if v.mode == want:
        nxt = Phase.HOLD if m.final_action == Request.HOLD else Phase.LAND
        return enter(state, nxt, t), Decision(setpoint=None, events=(f"vehicle in {want}",))
    new, dec = navigate(state, obs, m)
    return replace(new, phase=Phase.ARRIVED, since_s=state.since_s), replace(dec, request=Request(m.final_action))
