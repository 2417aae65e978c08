"""The values the mission state machine (:mod:`mission.phases`) reads, keeps and returns (pure).

Phases and abort reasons, what one tick observes (vehicle, carrier), the fixed model of a
mission, the state kept between ticks and the decision of a tick, plus two helpers every phase
uses: :func:`enter` (a new phase) and :func:`dock_point`.

Frames: local NED [m], [m/s]; times [s] on the controller's clock.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from enum import StrEnum

import numpy as np

from mission.phases.phase import Phase
from mission.interfaces import Request
from mission.core.safety import SafetyConfig
from mission.core.setpoint import Setpoint
from mission.core.tick import TickModel
from mission.core.tracking import TrackingGains

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
    """The carrier's newest state: position/velocity NED [m], [m/s]; age [s]; liveliness;
    acceleration NED [m/s^2] as the carrier measured it, or None (it sent none)."""

    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    age_s: float
    alive: bool | None = True
    acceleration_ned_m_s2: np.ndarray | None = None


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
    reason: AbortReason | None = None  # why the mission aborted (ABORT only)
    detail: str = ""
    x_ref: np.ndarray | None = None  # reference passenger position [m] NED
    e_ref: np.ndarray | None = None  # reference error to the anchor [m]
    anchor: np.ndarray | None = None  # latched anchor after separation [m]
    prev_dock: np.ndarray | None = None
    separation_time_s: float | None = None
    arrived_since_s: float | None = None
    u_ref: np.ndarray | None = None
    u_cmd: np.ndarray | None = None
    integral: np.ndarray | None = None  # tracking integral (mission.core.tracking)
    settled_since_s: float | None = None  # JOIN: since when the vehicle has been on the dock point


@dataclass(frozen=True)
class Decision:
    """What the controller does this tick. setpoint: what to send (velocity only or full, as
    tracking decided; None: send nothing); request: the vehicle command to have in flight
    (:class:`~mission.interfaces.Request`) or None.
    Diagnostics for the flight log: dock, P, relative (law's u_p - u_c), desired, safety_acted."""

    setpoint: Setpoint | None
    request: Request | None = None
    dock: np.ndarray | None = None
    P: float = float("nan")
    relative: np.ndarray | None = None
    desired: np.ndarray | None = None
    safety_acted: bool = False
    events: tuple[str, ...] = ()


ZERO = np.zeros(3)

def enter(state: MissionState, phase: Phase, t: float, **kw) -> MissionState:
    """``state`` in ``phase`` since ``t`` [s], with the fields ``kw`` changed."""
    return replace(state, phase=phase, since_s=t, **kw)


def dock_point(obs: Observation, m: MissionModel) -> np.ndarray:
    """Dock point [m] NED now: the carrier's last position moved on by its velocity over the
    sample's age (a late sample would otherwise pull the passenger back by speed x age), plus
    the dock offset."""
    c = obs.carrier
    assert c is not None  # every caller checked it
    return c.position_ned_m + c.velocity_ned_m_s * c.age_s + m.dock_offset_ned_m
