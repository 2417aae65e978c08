"""After a stall (pure): the first tick after a gap with no tick goes on from where the vehicle is.

A companion computer stalls (garbage collection, I/O, a busy CPU, a stopped process): for the
gap nothing is sent and PX4 flies the last setpoint it has (its position, velocity and
acceleration) until ``COM_OF_LOSS_T`` runs out, when its offboard-loss failsafe takes over
(docs/safety.md). Meanwhile the reference, which advances one tick per tick, has stood still,
and the vehicle has not: after 1 s it is a metre or more from it. Sent as it is, the reference's
next setpoint would pull PX4 back to where it was (its position loop, ``MPC_XY_P`` x the
distance: a jump in the velocity it flies). So:

::

    a gap between two ticks longer than STALL_S, in a flying phase (not seated on a deck):
      JOIN, SEPARATED .. ARRIVED, RETURNING .. FALLBACK, HOME --the reference (x_ref, u_ref;
          after separation e_ref) restarts on the vehicle's position and velocity
      RIDING --the reference (x_ref, u_ref) restarts on the vehicle's position and velocity
          too, and chases the dock point (mission.phases.flying: at most
          mission.dock_rejoin_speed_m_s relative to it, at the passenger's acceleration limit)
          until it is on it again. For the gap PX4 flew the last full setpoint, whose position
          stayed where the dock point was: its position loop braked the vehicle towards it while
          the carrier drove on, and the vehicle lies behind the dock point (0.7 m after 1 s at
          2 m/s); a reference left on the dock point would pull it there by PX4's position
          loop, a jump in what PX4 flies once full setpoints resume. The carrier's state the
          loop finds may be older than mission.carrier_timeout_s (the feed's thread stalled
          too): the chase goes on, on the dock point predicted with its age, and the latch
          waits for a fresh one (mission.phases.machine)
      TRANSIT, riding on an untrusted feed --the reference stays on the dock point
      every one --the last command (u_cmd, the safety filter's previous one) is the vehicle's
          velocity, so the command goes on from what the vehicle does, within the passenger's
          acceleration limit per tick; the dwell being timed (JOIN's, the holdoff's) restarts
      APPROACH, the gap longer than recovery.carrier_max_age_s --GO_AROUND
          (mission.phases.recovery.approach): the approach went unwatched for longer than a
          carrier state may be old on it, and a new one starts from the holdoff point
    for SETTLE_S after the gap --the same restart every tick, and the setpoint sent as velocity
          only (the command; no position for PX4 to pull the vehicle to); with no vehicle
          position read since the gap yet, the last command again (not the stop that a silent
          link gets: mission.phases.machine)

The settling: the link's receiving thread stalled with the loop, and the first ticks after the
gap read its backlog, a second of telemetry, oldest first (the vehicle's position is moved on by
its velocity over at most TELEMETRY_SILENT_S of its age). A reference restarted once on such a
position lies behind the vehicle, and PX4's position loop brakes the vehicle towards it (what
that did on the mock: docs/recovery.md, "A stalled controller"). Restarted every tick while the
backlog drains (about 0.1 s), and flown by velocity meanwhile, it goes on from where the vehicle
really is.

Frames: local NED [m], [m/s]; times [s] on the controller's clock.
"""
from __future__ import annotations

from mission.core.records import replace

from mission.core.setpoint import Setpoint
from mission.phases.phase import Phase
from mission.phases.types import ZERO, Decision, MissionState, Observation

#: [s] a gap between two ticks longer than this is a stall (at 50 Hz, 12 ticks missed): longer
#: than the loop's usual late ticks on a loaded machine (0.1-0.2 s, docs/recovery.md), shorter
#: than a carrier state's budget on the approach (recovery.carrier_max_age_s, 0.3 s).
STALL_S = 0.25

#: [s] after the first tick after a stall: the reference restarts on the vehicle every tick and
#: flies by velocity only, while the link reads the telemetry it missed (see above).
SETTLE_S = 0.2

#: Phases whose reference sits on the dock point: not moved after a stall (RIDING on a trusted feed
#: is: it restarts on the vehicle and chases the dock point, see :func:`resume`).
ON_THE_DOCK = frozenset({Phase.RIDING, Phase.TRANSIT})

#: Phases whose reference is the paper's law integrated about the anchor (``e_ref``).
ABOUT_THE_ANCHOR = frozenset({Phase.SEPARATED, Phase.NAVIGATING, Phase.ARRIVED})


def gap_s(state: MissionState, t_s: float) -> float:
    """Time [s] since the last tick (0 before the first)."""
    return 0.0 if state.tick_s is None else t_s - state.tick_s


def stalled(state: MissionState, t_s: float) -> bool:
    """True on the first tick after a stall: more than :data:`STALL_S` since the last tick."""
    return gap_s(state, t_s) > STALL_S


def begin(state: MissionState, t_s: float) -> MissionState:
    """``state`` with ``last_stall`` = (``t_s``, the gap) on the first tick after a stall in a
    flying phase (not seated on a deck): the settling begins (unchanged on any other tick)."""
    if stalled(state, t_s) and state.phase.flying and not state.seated:
        return replace(state, last_stall=(t_s, gap_s(state, t_s)))
    return state


def settling(state: MissionState, t_s: float) -> bool:
    """True for :data:`SETTLE_S` from the first tick after a stall (:func:`begin`)."""
    return state.last_stall is not None and 0.0 <= t_s - state.last_stall[0] < SETTLE_S


def resume(state: MissionState, obs: Observation) -> tuple[MissionState, tuple[str, ...]]:
    """``state`` ready for a tick while :func:`settling` after a stall (unchanged on any other
    tick), and on the first, the event saying so. The reference restarts on the vehicle (see the
    module's table); the vehicle must be known with a valid position (else the failsafes have
    acted already)."""
    v, t = obs.vehicle, obs.t_s
    if not settling(state, t) or not state.phase.flying or state.seated or state.x_ref is None \
            or v is None or not v.position_valid:
        return state, ()
    x_p, v_p = v.position_ned_m.copy(), v.velocity_ned_m_s.copy()
    state = replace(state, u_cmd=v_p.copy(), settled_since_s=None)
    if state.phase is Phase.RIDING and state.held_dock is None:
        state = replace(state, x_ref=x_p.copy(), u_ref=v_p.copy(), chasing_dock=True)
    elif state.phase not in ON_THE_DOCK:
        state = replace(state, x_ref=x_p.copy(), u_ref=v_p.copy())
        if state.phase in ABOUT_THE_ANCHOR and state.anchor is not None:
            state = replace(state, e_ref=x_p - state.anchor)
    if state.recovery is not None and state.phase is Phase.HOLDOFF:
        state = replace(state, recovery=replace(state.recovery, settled_since_s=None))
    return state, _said(state, t)


def _said(state: MissionState, t_s: float) -> tuple[str, ...]:
    """The stall's event on the first tick after it (none on any other)."""
    if state.last_stall is None or state.last_stall[0] != t_s:
        return ()
    # what the restart does (:func:`resume`), read from the phase, not from the state's chasing
    # flag: with the vehicle's position not read again yet (:func:`unread`) the event is said before
    # the restart, and said "on the dock point" for a ride about to chase it (one run in two of
    # tests/faults/test_stall_faults.py on a loaded machine)
    chases = state.phase is Phase.RIDING and (state.chasing_dock or (state.held_dock is None and not state.seated))
    where = ("from the vehicle, chasing the dock point" if chases
             else "on the dock point" if state.phase in ON_THE_DOCK else "from the vehicle")
    return (f"stalled: no tick for {state.last_stall[1]:.2f} s; the reference goes on {where}, "
            f"the command from the vehicle's velocity (by velocity only for {SETTLE_S:g} s)",)


def unread(state: MissionState, t_s: float) -> Decision:
    """While settling, the vehicle's position not read again yet (the link's thread stalled with
    the loop; its last position is older than TELEMETRY_SILENT_S): the last command, by velocity
    only, not a stop (a stop would be the jump this module avoids); on the first tick after the
    stall, its event too (the restart comes once a position is read)."""
    u = state.u_cmd if state.u_cmd is not None else ZERO
    return Decision(setpoint=Setpoint(velocity_ned_m_s=u.copy()),
                    events=(*_said(state, t_s), "no vehicle position read since the stall yet"))


def by_velocity(decision: Decision) -> Decision:
    """``decision`` with its setpoint (if any) sent as velocity only: its velocity and yaw."""
    sp = decision.setpoint
    if sp is None or sp.position_ned_m is None:
        return decision
    return replace(decision, setpoint=Setpoint(velocity_ned_m_s=sp.velocity_ned_m_s, yaw_rad=sp.yaw_rad))
