"""The values the mission state machine (:mod:`mission.phases`) reads, keeps and returns (pure).

Phases and abort reasons, what one tick observes (vehicle, carrier), the fixed model of a
mission, the state kept between ticks and the decision of a tick, plus two helpers every phase
uses: :func:`enter` (a new phase) and :func:`dock_point`.

Frames: local NED [m], [m/s]; times [s] on the controller's clock.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any
from enum import StrEnum

import numpy as np

from mission.core.records import replace
from mission.phases.measurements import Measurements
from mission.phases.phase import Phase, Request
from mission.core.safety import DeckKeepOut, Neighbours, SafetyConfig
from mission.core.docking import DockingGeometry
from mission.core.pursuit import PursuitLimits
from mission.core.setpoint import Setpoint
from mission.core.tick import TickModel
from mission.core.tracking import TrackingGains
from mission.relnav.estimator import RelnavParams
from mission.relnav.inputs import RelativeEstimate

TELEMETRY_SILENT_S = 0.4  # position older than this (PX4 streams it at 30 Hz): the link went quiet [s]


class AbortReason(StrEnum):
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
    VEHICLE_DISARMED = "vehicle_disarmed"
    VEHICLE_AMBIGUOUS = "vehicle_ambiguous"
    NONFINITE = "nonfinite"
    DECK_DISTURBED = "deck_disturbed"




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
    battery_pct: float | None = None  # battery remaining [%] as the vehicle reports it (None: not reported)
    # [m/s] NED: the estimator's velocity less ``velocity_ned_m_s`` when that was made consistent
    # with the position (mission.velocity_bias_tau_s; mission.core.consistent_velocity), else None
    velocity_bias_ned_m_s: np.ndarray | None = None
    on_ground: bool = False  # EXTENDED_SYS_STATE landed_state ON_GROUND: PX4's land detector says landed


@dataclass(frozen=True)
class CarrierObs:
    """The carrier's newest state: position/velocity NED [m], [m/s]; age [s] since the carrier
    measured it, good to ``age_bound_s`` [s] (the clock offset's bound; None: the measurement time
    is unknown, no round trip yet, and ``age_s`` is the time since it arrived); liveliness;
    acceleration NED [m/s^2] as the carrier measured it, or None (it sent none); untrusted: why
    the feed does not trust it yet (just bound, a resync, a contested source), None when it does;
    ``own_frame_position_ned_m`` [m] NED: where the carrier itself says it is (its published
    position, in its own GNSS frame) when its law runs there (``carrier.p3_frame = "own"``) and
    ``position_ned_m`` was moved into the passenger's frame (the relative estimator); None: the
    same as ``position_ned_m``, or its law runs in the passenger's frame too;
    ``stamp_s`` [s] the sample's measurement time on the carrier's own clock (the wire's ``stamp``;
    None: unknown), which tells a new measurement from the same one sent or aged again: ``t - age_s``
    moves by the clock offset's corrections while the measurement stays the same, and a carrier may
    publish one GNSS fix several times (a new ``seq`` each, the same stamp)."""

    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    age_s: float
    alive: bool | None = True
    acceleration_ned_m_s2: np.ndarray | None = None
    yaw_rad: float | None = None  # [rad] its heading, if it sent one
    untrusted: str | None = None
    age_bound_s: float | None = 0.0
    own_frame_position_ned_m: np.ndarray | None = None
    stamp_s: float | None = None

    @property
    def law_position_ned_m(self) -> np.ndarray:
        """[m] NED the position the carrier's own law runs at (the class docstring)."""
        return self.position_ned_m if self.own_frame_position_ned_m is None else self.own_frame_position_ned_m

    @property
    def worst_age_s(self) -> float:
        """The oldest the state may be [s]: its age plus the bound (the receive age when unknown)."""
        return self.age_s + (self.age_bound_s or 0.0)


@dataclass(frozen=True)
class Observation:
    """What one tick sees. ``failed`` maps a request ("arm", "offboard") to the vehicle's reason
    once the controller gave up on it after its retries; ``measurements``: the measurement feeds'
    readings (:mod:`mission.phases.measurements`: this tick's and the newest of each kind)."""

    t_s: float
    vehicle: VehicleObs | None
    carrier: CarrierObs | None
    failed: dict[str, str] = field(default_factory=dict)
    interrupted: bool = False
    measurements: Measurements = Measurements()
    relative: RelativeView | None = None  # the relative estimator's word on the deck ([relnav] enabled)
    neighbours: Neighbours | None = None  # the other passengers' shared states (the separation barrier's)
    # [m] NED the target the carrier announces it heads for (a carrier serving a team); None: not
    # announced, every target is this passenger's turn (one passenger; :func:`my_turn`)
    carrier_target_ned_m: np.ndarray | None = None


@dataclass(frozen=True)
class RelativeView:
    """The relative estimator's word on the deck this tick (``[relnav]`` enabled,
    :class:`mission.relnav.estimator.RelativeEstimator` run by the passenger's step):
    ``position_ned_m`` the deck minus the vehicle [m] NED; ``bias_ned_m`` the estimated bias of
    the carrier's GNSS frame over the passenger's [m]; ``pending_ned_m`` the part of the relative
    position's jumps the carrier's state the phases see has not taken in yet [m] (let through at most at
    ``relnav.correction_rate_m_s``); ``position_sigma_m`` [m] and ``converged`` as the estimate's;
    ``since_marker_s`` [s] since the capture of the newest marker fused (inf: none yet);
    ``estimate`` the estimator's whole output the above comes from (its covariance, velocities and
    counts: what the flight data logs; the phases read the fields above; None: not given);
    ``carrier_accel_ned_m_s2`` [m/s^2] NED the carrier's acceleration as the estimate shows it
    (``relnav.carrier_accel_tau_s`` > 0; None: not estimated, riding predicts the law's);
    ``inputs`` what the estimator was handed since the last view, in that order
    (:data:`mission.relnav.inputs.EstimatorInput` records: the flight log keeps them, and they
    replay the estimator exactly)."""

    position_ned_m: np.ndarray
    bias_ned_m: np.ndarray
    pending_ned_m: np.ndarray
    position_sigma_m: float
    converged: bool
    since_marker_s: float
    estimate: RelativeEstimate | None = None
    carrier_accel_ned_m_s2: np.ndarray | None = None
    inputs: tuple[Any, ...] = ()


@dataclass(frozen=True)
class RelnavGates:
    """How the phases use the relative estimate (``[relnav]``, docs/relnav.md): ``params`` the
    estimator's tuning; ``marker_timeout_s`` [s] the marker is in sight while its newest fused
    capture is this recent; ``descent_marker_timeout_s`` [s] below the decision height, this
    recent (no later than ``marker_timeout_s``); ``marker_memory_s`` [s] HOLDOFF begins an approach only with a marker
    this recent; ``search_s`` [s] how long HOLDOFF searches for the marker, and how long the
    descent holds with it lost; ``correction_rate_m_s`` [m/s] the bias correction's top rate;
    ``seated_sigma_m`` [m] how well standing on the deck places the vehicle over it;
    ``pending_limit_m`` [m] an approach begins only with the estimate's jumps taken in to this;
    ``marker_offset_ned_m`` (3,) [m] NED, the marker's centre from the carrier's reference point
    (``vision.marker_offset_ned_m``, the dock point unless set); ``carrier_accel_tau_s`` [s] the
    low-pass of the carrier's acceleration estimated from its velocity (0: none estimated);
    ``carrier_accel_m_s2`` [m/s^2] the carrier's acceleration limit (``relnav.velocity_slew_m_s2``,
    else ``safety.carrier_max_accel_m_s2``; None: unknown): the deck's velocity the phases see
    changes no faster, plus ``deck_velocity_catch_up_per_s`` [1/s] times how far it is behind the
    filter's (a lag beyond the noise is caught up); ``deck_radius_m`` [m] the deck's radius
    (``recovery.deck_radius_m``): a downward range is fused over it only."""

    params: RelnavParams
    marker_timeout_s: float
    descent_marker_timeout_s: float
    marker_memory_s: float
    search_s: float
    correction_rate_m_s: float
    seated_sigma_m: float
    pending_limit_m: float
    carrier_accel_tau_s: float
    marker_offset_ned_m: np.ndarray
    deck_velocity_catch_up_per_s: float
    deck_radius_m: float
    carrier_accel_m_s2: float | None = None
    carrier_law_own_frame: bool = True  # the carrier's law runs in its own GNSS frame (carrier.p3_frame "own")

    def descent_blocked(self, rel: RelativeView | None, below: bool = False) -> str | None:
        """Why the vehicle may not descend below the decision height now (None: it may): the
        marker in sight (``below`` the decision height already: within ``descent_marker_timeout_s``,
        else ``marker_timeout_s``) and the estimate converged."""
        if rel is None:
            return "no relative estimate"
        if rel.since_marker_s > (self.descent_marker_timeout_s if below else self.marker_timeout_s):
            return "marker not in sight" if math.isinf(rel.since_marker_s) else \
                f"marker not in sight for {rel.since_marker_s:.1f} s"
        if not rel.converged:
            return f"relative estimate not converged (sigma {rel.position_sigma_m:.2f} m)"
        return None

    def acquired(self, rel: RelativeView | None) -> bool:
        """The marker fused within ``marker_memory_s``: HOLDOFF need not search for it."""
        return rel is not None and rel.since_marker_s <= self.marker_memory_s

    def taken_in(self, rel: RelativeView | None) -> bool:
        """The estimate's jumps taken in by the carrier's state the phases see (within
        ``pending_limit_m``): an approach may begin."""
        return rel is not None and float(np.linalg.norm(rel.pending_ned_m)) <= self.pending_limit_m


@dataclass(frozen=True)
class MissionModel:
    """Fixed parameters of a mission, built from the configuration (:func:`mission.model.mission_model`):
    no field taken from it has a default here, the schema holds the one default of each."""

    tick: TickModel
    command_safety: SafetyConfig  # limits on what is sent to the vehicle
    dock_offset_ned_m: np.ndarray
    dock_tolerance_m: float
    track_gain: float
    join_speed_m_s: float
    arrival_radius_m: float
    arrival_dwell_s: float
    final_action: str  # "hold" | "land"
    carrier_timeout_s: float  # [s] before separation, a carrier state older than this is not fresh (no latch on it)...
    carrier_lost_s: float  # ... and none fresh for this long [s]: carrier_lost
    dock_chase: PursuitLimits  # riding a stale carrier state and back: the reference's limits relative to the dock point
    riding_safety: SafetyConfig | None  # riding: the reference's limits (safety.riding_max_accel_m_s2; None: the tick's)
    riding_command_safety: SafetyConfig | None  # ... and the command's (None: command_safety)
    heartbeat_timeout_s: float
    prestream_s: float
    connect_timeout_s: float
    max_duration_s: float
    dt_s: float
    tracking: TrackingGains
    near_deck_damping_per_s: float | None  # [1/s] the tracking's damping in HOLDOFF and APPROACH (None: the tracking's)
    join_settle_m: float  # JOIN -> RIDING within this of the dock point [m] (min with the tolerance)...
    join_settle_s: float  # ... for this long [s]
    arrival_max_speed_m_s: float | None  # arrival also needs the vehicle this slow [m/s]
    carrier_dt_s: float  # the carrier's control period [s] (its acceleration over one step)
    carrier_accel_horizon_s: float  # [s] the law's acceleration fed forward: over this, or one carrier step if longer
    recovery: RecoveryModel | None  # with final_action "return"
    leg_start_m: float  # a leg after the first starts once the carrier is this far from its target [m]
    deck: DeckRide | None  # mission.ride = "deck": the passenger sits on the deck (the dock point) when carried
    relnav: RelnavGates | None  # [relnav] enabled: the phases fly the relative estimate
    queue: QueueModel | None  # the recovery queue among the team's passengers (None: as if alone)
    legs: tuple[MissionModel, ...] = ()  # one model per target, in order (the leg's tick has its target)
    next_target: np.ndarray | None = None  # a leg's model: the target of the leg after it [m] NED, or None (the last)


@dataclass(frozen=True)
class QueueModel:
    """The recovery queue (``[team]``'s ``queue_*``; docs/team.md, :mod:`mission.phases.queue`):
    a waiting passenger holds off ``distance_m`` [m] farther behind its holdoff point along the
    carrier's course and ``height_m`` [m] higher; it falls back after waiting ``timeout_s`` [s]
    without a break; with at most ``must_pct`` [%] (recovery.battery_reserve_pct +
    team.queue_battery_pct) left it must land (it goes first, the lowest first); ``rank``: its own
    MAVLink system id (the tie-break of two that asked at once: the lower first; None: unknown);
    ``deck_clearance_m`` [m]: the least distance kept from the other passengers while it
    approaches and docks (team.passenger_span_m: tip to tip), where ``safety.passenger_separation_m``
    would forbid the deck's neighbouring slots; ``separation_m`` [m] the distance kept from them
    in the recovery's air phases (safety.passenger_separation_m + safety.margin_m: the barrier
    holds the references apart on the positions the others report, and both estimates err)."""

    distance_m: float
    height_m: float
    timeout_s: float
    must_pct: float
    rank: int | None
    deck_clearance_m: float
    separation_m: float


@dataclass(frozen=True)
class DeckRide:
    """Riding on the carrier's deck (``mission.ride = "deck"``; docs/deck-riding.md): the dock point is
    the deck. ``arm_lead_s`` [s]: streaming, arming and OFFBOARD begin this long before the
    predicted separation; the keep-out round the deck (:class:`mission.core.safety.DeckKeepOut`):
    ``keep_out_radius_m`` [m], ``slope`` [-], ``clear_height_m`` [m]; ``press_m`` [m]: how far
    below the vehicle's reported height (or, disarmed, the deck's plane) the landing presses the
    reference (so the vehicle settles on it); ``press_floor_m`` [m]: never deeper than this below
    the deck's plane; ``radius_m`` [m]: the deck's radius round the dock point (only over it does
    the landing press below the reported height)."""

    arm_lead_s: float
    keep_out_radius_m: float
    slope: float
    clear_height_m: float
    press_m: float = 0.1
    press_floor_m: float = 0.5
    radius_m: float = 0.5

    def keep_out(self, obs: Observation, m: MissionModel) -> DeckKeepOut | None:
        """The deck's keep-out now (None without a carrier state)."""
        if obs.carrier is None:
            return None
        return DeckKeepOut(dock_point(obs, m), np.asarray(obs.carrier.velocity_ned_m_s, dtype=float),
                           self.keep_out_radius_m, self.slope, self.clear_height_m)


@dataclass(frozen=True)
class RecoveryModel:
    """How the passenger comes home (``mission.final_action = "return"``; docs/recovery.md).

    geometry: holdoff, glide path, gate, cone, contact; ``returning``/``approach``: the reference's
    limits relative to the carrier [m/s], [m/s^2]; the final descent's speed [m/s] and how long
    [s] the vehicle may take to line up at the gate; settle radius [m] / speed [m/s] / dwell [s]
    and the carrier's least speed [m/s] (HOLDOFF -> APPROACH); carrier limits on the approach: state age [s], acceleration [m/s^2],
    turn rate [rad/s]; ``carrier_lost_s`` [s] without a fresh state: fall back; attempts and
    timeout [s]; fallback "hold" (at ``fallback_height_m`` [m] above the dock,
    ``fallback_offset_m`` [m] off the carrier's path) or "land" (at ``fallback_point_ned_m``);
    battery reserve [%] and the flight time [s] allowed for docking; ``at_target_s`` [s] of task;
    ``keep_out_m`` [m]: the target's keep-out (b c) that no recovery point may lie in."""

    geometry: DockingGeometry
    returning: PursuitLimits
    approach: PursuitLimits
    descent_speed_m_s: float
    final_descent_speed_m_s: float | None  # [m/s] the descent's last three contact heights (None: descent_speed_m_s)
    final_lineup_margin: float  # [-] below two contact heights: lined up with this fraction of the contact radius to spare
    final_descent_lag_m: float | None  # [m] below three contact heights: the reference at most this far below the vehicle
    gate_timeout_s: float
    settle_radius_m: float
    settle_speed_m_s: float
    settle_dwell_s: float
    settle_carrier_speed_m_s: float
    docked_dwell_s: float
    carrier_max_age_s: float
    carrier_max_accel_m_s2: float
    carrier_max_turn_rate_rad_s: float
    carrier_rate_window_s: float  # [s] the carrier's acceleration and turn rate are measured over its samples of this long
    carrier_lost_s: float
    max_attempts: int
    timeout_s: float
    fallback: str  # "hold" | "land"
    fallback_point_ned_m: np.ndarray | None
    fallback_height_m: float
    fallback_offset_m: float
    battery_reserve_pct: float
    docking_budget_s: float
    at_target_s: float
    deck_radius_m: float
    keep_out_m: float
    carrier_return_max_age_s: float  # [s] the age budget of RETURNING, HOLDOFF and GO_AROUND


CarrierSamples = tuple[tuple[float, float, float, float], ...]
"""The carrier's velocity samples, oldest first: (t [s] on the controller's clock when the carrier
sampled it, ``t - age``; v_n, v_e [m/s] NED; its heading [rad] as it sent it, NaN: none)."""


@dataclass(frozen=True)
class RecoveryState:
    """What the recovery remembers (frozen; phases return a new one).

    started_s [s] on the mission clock; why it began ("task done" | "battery"); approaches begun;
    course: the carrier's course (horizontal unit vector NED); ``s``: progress on the glide path
    [0, 1], then ``descent`` on the vertical descent from the gate; ``climb_to`` [m]: a go-around's climb goal relative to the dock point (None: climbed);
    the carrier's velocity samples over the last ``carrier_rate_window_s`` (its acceleration and turn rate); the last
    time a fresh carrier state was seen [s]; since when the vehicle has settled or held contact [s];
    the contact figures at docking; the fallback's reason and goal [m]; the battery when the flight
    began (t [s], remaining [%]): its drain rate."""

    started_s: float
    why: str
    attempts: int = 0
    course: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    s: float = 0.0
    descent: float | None = None  # progress [0, 1] of the vertical descent from the gate (None: not begun)
    climb_to: np.ndarray | None = None
    carrier_samples: CarrierSamples = ()
    carrier_seen_s: float | None = None
    settled_since_s: float | None = None
    settled_offset_m: np.ndarray | None = None  # HOLDOFF: the vehicle's offset from the holdoff point at settled_since_s
    contact: dict[str, Any] | None = None
    fallback_why: str = ""
    fallback_goal: np.ndarray | None = None
    search_since_s: float | None = None  # [relnav] HOLDOFF searching for the marker since [s]
    marker_lost_s: float | None = None  # [relnav] the descent has had the marker lost since [s]
    descent_since_s: float | None = None  # [s] the descent from the gate began (None: not descending)
    queued_since_s: float | None = None  # [s] waiting its turn in the recovery queue since (None: not waiting)
    queued_for: str | None = None  # why it waits (the neighbour ahead), for the events
    queue_place: int = 0  # waiting: its queue point's level, 1 + how many wait ahead of it (0: not waiting)


@dataclass(frozen=True)
class MissionState:
    """Everything the machine remembers between ticks (immutable; ``step`` returns a new one)."""

    phase: Phase = Phase.PREFLIGHT
    since_s: float = 0.0
    start_s: float | None = None
    reason: AbortReason | None = None  # why the mission aborted (ABORT only)
    detail: str = ""
    x_ref: np.ndarray | None = None  # reference passenger position [m] NED
    e_ref: np.ndarray | None = None  # reference error to the anchor [m]
    anchor: np.ndarray | None = None  # latched anchor after separation [m]
    prev_dock: np.ndarray | None = None
    separation_time_s: float | None = None
    arrival_window: tuple[tuple[float, np.ndarray], ...] = ()  # recent positions within the arrival radius (mission.core.arrival)
    u_ref: np.ndarray | None = None
    u_cmd: np.ndarray | None = None
    integral: np.ndarray | None = None  # tracking integral (mission.core.tracking)
    accel_lp: np.ndarray | None = None  # low-passed reference acceleration [m/s^2] (tracking.lead_acceleration)
    settled_since_s: float | None = None  # JOIN: since when the vehicle has been on the dock point
    recovery: RecoveryState | None = None  # bringing the passenger home (RECOVERY phases, FALLBACK, HOME)
    leg: int = 0  # index of the target being served (scenario.targets)
    legs_done: tuple[dict[str, Any], ...] = ()  # what each finished leg did (target, separation, contact, outcome)
    legs_skipped: str | None = None  # why the legs after the last one flown were skipped (None: none were)
    battery_start: tuple[float, float] | None = None  # (t [s], remaining [%]) at the first battery reading
    held_dock: np.ndarray | None = None  # [m] NED: holding on (then rejoining from) this dock point: the feed was untrusted
    chasing_dock: bool = False  # riding: the reference chases the dock point (a stale state ridden, then back on a fresh one)
    # ride = "deck": the passenger sits on the deck (carried, taking off or landed): PX4 may show it
    # disarmed, landed or out of OFFBOARD without that being a fault (mission.phases.machine)
    seated: bool = False
    streaming_since_s: float | None = None  # seated: since when setpoints stream before arming [s] (None: not yet)
    # seated, the mission asking nothing of the vehicle: (seen disarmed since, PX4's mode then) (mission.phases.deck.watch)
    deck_watch: tuple[bool, str] | None = None
    # seated, streaming before the latch: the position [m] NED the last setpoint sent (None: velocity only; NaN on
    # an axis sent velocity only)
    seated_sent: np.ndarray | None = None
    # the take-off from the deck: (offset [m], its rate [m/s]) NED of the point tracked from the reference, which
    # starts where the passenger was when the latch fired and relaxes to zero (mission.phases.flying.navigate)
    takeoff_offset: tuple[np.ndarray, np.ndarray] | None = None
    tick_s: float | None = None  # the last tick's time [s]: a longer gap to this one is a stall (mission.phases.stall)
    last_stall: tuple[float, float] | None = None  # (the first tick after the last stall [s], its gap [s]) (mission.phases.stall)
    carrier_fresh_s: float | None = None  # the last tick [s] that saw a fresh carrier state (mission.carrier_timeout_s)


@dataclass(frozen=True)
class Decision:
    """What the controller does this tick. setpoint: what to send (velocity only or full, as
    tracking decided; None: send nothing); request: the vehicle command to have in flight
    (:class:`~mission.phases.phase.Request`) or None.
    Diagnostics for the flight log: dock, P, relative (law's u_p - u_c), desired, safety_acted."""

    setpoint: Setpoint | None
    request: Request | None = None
    dock: np.ndarray | None = None
    P: float = float("nan")
    relative: np.ndarray | None = None
    desired: np.ndarray | None = None
    safety_acted: bool = False
    events: tuple[str, ...] = ()
    home_ned_m: np.ndarray | None = None  # [m] NED: where PX4's home should be now (the dock point), or None


ZERO = np.zeros(3)

def enter(state: MissionState, phase: Phase, t: float, **kw) -> MissionState:
    """``state`` in ``phase`` since ``t`` [s], with the fields ``kw`` changed."""
    return replace(state, phase=phase, since_s=t, **kw)


def finish_leg(state: MissionState, obs: Observation, outcome: str) -> MissionState:
    """``state`` with the current leg's record appended to ``legs_done``."""
    rec = state.recovery
    leg = {"leg": state.leg, "outcome": outcome, "end_s": obs.t_s,
           "separation_time_s": state.separation_time_s,
           "anchor_ned_m": None if state.anchor is None else [float(x) for x in state.anchor],
           "contact": None if rec is None else rec.contact,
           "recovery_why": None if rec is None else rec.why}
    return replace(state, legs_done=(*state.legs_done, leg))


def describe_age(c: CarrierObs) -> str:
    """``c``'s age in words: since the carrier measured it (with the bound), or since it arrived."""
    if c.age_bound_s is None:
        return f"{c.age_s:.2f} s old since it arrived (when the carrier measured it is not known)"
    bound = f" +- {c.age_bound_s:.3f}" if c.age_bound_s > 0 else ""
    return f"{c.age_s:.2f}{bound} s old since the carrier measured it"


def carrier_fresh(obs: Observation, m: MissionModel) -> bool:
    """A carrier state fresh enough to ride on and separate on: present, its liveliness token not
    gone, measured no longer than ``mission.carrier_timeout_s`` ago (with the bound). An older
    one (a stalled carrier process or link) is still ridden, predicted with its age
    (:func:`dock_point`), for ``mission.carrier_lost_s`` (:mod:`mission.phases.machine`), but
    the latch waits for a fresh one."""
    c = obs.carrier
    return c is not None and c.worst_age_s <= m.carrier_timeout_s and c.alive is not False


#: [m] how close the carrier's announced target must be to this passenger's leg's to be the same one
#: (both are the file's numbers: the same target is the same floats, distinct targets are > b c apart)
SAME_TARGET_M = 1e-3


def my_turn(obs: Observation, m: MissionModel) -> bool:
    """Whether the carrier heads for this passenger's leg's target: its announced target
    (``obs.carrier_target_ned_m``) is the leg's (within :data:`SAME_TARGET_M`), or it announces
    none (one passenger: always its turn). The latch (and, on the deck, the arming before it)
    waits for its turn: a carrier that serves another passenger of its team may pass within
    ``b c`` of this one's target on the way (docs/team.md)."""
    aim = obs.carrier_target_ned_m
    if aim is None:
        return True
    target = np.asarray(m.tick.target, dtype=float)
    return bool(np.linalg.norm(np.asarray(aim, dtype=float)[:target.shape[-1]] - target) <= SAME_TARGET_M)


def dock_point(obs: Observation, m: MissionModel) -> np.ndarray:
    """Dock point [m] NED now: the carrier's last position moved on by its velocity over the
    sample's age (a late sample would otherwise pull the passenger back by speed x age), plus
    the dock offset."""
    c = obs.carrier
    assert c is not None  # every caller checked it
    return c.position_ned_m + c.velocity_ned_m_s * c.age_s + m.dock_offset_ned_m
