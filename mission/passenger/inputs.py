"""What the passenger's step reads, as pure records (numpy only, no link, no bus, no clock): the
vehicle as a link or a simulated vehicle reports it (:class:`VehicleReport`), and one tick's raw
observations (:class:`PassengerInputs`: the vehicle, the carrier, the measurement feeds'
readings). The MAVLink side turns its
:class:`~mission.mavlink.telemetry.VehicleState` into a :class:`VehicleReport`
(:func:`mission.mavlink.telemetry.vehicle_report`); the simulator's vehicle makes one directly."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from mission.core.safety import Neighbours
    from mission.phases.measurements import Measurement
    from mission.phases.types import CarrierObs


@dataclass(frozen=True)
class VehicleReport:
    """The vehicle as the link saw it when read at ``t_s`` [s] (the reader's clock).

    position_ned_m, velocity_ned_m_s: its last position/velocity sample [m], [m/s] NED (None:
    none yet); sample_t_s: when the vehicle took that sample, on the reader's clock [s] (None:
    unknown); rx_s: when the sample arrived [s] (None: none yet); armed, mode: what it says it is
    (its believed armed state, PX4's mode name); heartbeat_age_s: since its last HEARTBEAT [s];
    valid: its position is fresh, finite and its estimator healthy; in_failsafe: the autopilot
    runs one of its failsafes; battery_pct: remaining [%] (None: not reported); on_ground: its
    land detector says landed (as believed).
    """

    t_s: float
    position_ned_m: np.ndarray | None
    velocity_ned_m_s: np.ndarray | None
    sample_t_s: float | None
    rx_s: float | None
    armed: bool
    mode: str
    heartbeat_age_s: float
    valid: bool
    in_failsafe: bool = False
    battery_pct: float | None = None
    on_ground: bool = False


@dataclass(frozen=True)
class PassengerInputs:
    """One tick's raw observations: the tick's time ``t_s`` [s]; the vehicle's report (None: no
    vehicle heard yet); the carrier's newest state with its age (None: none yet); ``failed``: the
    requests ("arm", "offboard") the vehicle refused after their retries, and other reasons the
    mission cannot go on (signing, identity), each with its reason; ``interrupted``: the user
    asked the mission to stop; ``measurements``: what the measurement feeds
    (:class:`mission.interfaces.MeasurementSource`) gave since the last tick, each reading once,
    stamped at capture (:mod:`mission.phases.measurements`); ``neighbours``: the other passengers'
    last shared states with their ages (None: none heard; no bus feeds them yet), which the
    separation barrier keeps this one apart from while it flies to its target;
    ``carrier_target_ned_m`` [m] NED: the target the carrier announces it heads for (a carrier
    serving a team, :class:`mission.carrier.team.TeamCarrier`; None: none announced, every target
    is this passenger's turn), which its latch waits for (:func:`mission.phases.types.my_turn`)."""

    t_s: float
    vehicle: VehicleReport | None
    carrier: CarrierObs | None
    failed: dict[str, str] = field(default_factory=dict)
    interrupted: bool = False
    measurements: tuple[Measurement, ...] = ()
    neighbours: Neighbours | None = None
    carrier_target_ned_m: np.ndarray | None = None
