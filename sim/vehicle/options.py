"""What a :class:`sim.vehicle.mock.MockVehicle` is made with (:class:`VehicleOptions`) and what it
reports of itself (:class:`VehicleSnapshot`)."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from mission.config.relnav import PassengerGnssSection, RangefinderSection
from mission.mavlink import px4
from sim.vehicle.estimator import PX4_SITL_SCALE
from sim.vehicle.faults import FaultOptions
from sim.vehicle.modes import TrajectorySetpoint
from sim.vehicle.physics.deck import DeckSpec, Touchdown

FRAMES = {"quadrotor": px4.MAV_TYPE_QUADROTOR, "rover": px4.MAV_TYPE_GROUND_ROVER}

@dataclass(frozen=True)
class VehicleOptions:
    """How to run a :class:`MockVehicle`. Units: [s] simulated, [m] NED, [m/s], [deg] for lat/lon.

    bind: local UDP address (``HOST:PORT`` or a pymavlink ``udpin:`` URL); port 0 = ephemeral.
    target: where it sends from start-up (onboard link); it latches on the first peer that talks.
    gcs_target / gcs_bind: optional second link (PX4's GCS link sends to 14550).
    speed: clock speed factor; all rates and timeouts scale with it.
    home: EKF origin (lat [deg], lon [deg], alt [m AMSL]) of the local NED frame.
    start_ned: start position [m] NED; on the ground when ``d >= 0``, on a platform when ``d < 0``.
    params: PX4 parameter overrides, e.g. ``{"COM_OF_LOSS_T": 1.0}``.
    wind_ned_m_s: wind [m/s] NED: a drag force in the air, which PX4's velocity integrator slowly
    compensates. position_noise_m: sigma of the Gaussian noise on the reported position [m]
    (seeded by ``faults.seed``). estimate_error: a quadrotor's estimate errs as PX4 SITL's does
    (its velocity and position errors, :mod:`sim.vehicle.estimator`, seeded by ``faults.seed``),
    this many times as much: 1 (default) is PX4 SITL's, 0 an exact estimate.
    PX4's controller flies the estimate and the telemetry reports it.
    signing_key: 32-byte MAVLink 2 signing key; then unsigned messages other than HEARTBEAT
    are rejected and everything sent is signed.
    deck: the carrier's deck under the vehicle (:mod:`sim.vehicle.physics.deck`), its motion
    given by :meth:`MockVehicle.follow_deck` (``mock-vehicle --deck PAIR``: the carrier's Zenoh
    state); None: no deck.
    lockstep: own simulated time and step in lockstep with the controller on the onboard link
    (:mod:`mission.bus.lockstep`); ``speed`` is then the pace after the controller leaves or stays
    silent for ``lockstep_watchdog_wall_s`` wall seconds. ``lockstep_max_speed``: in lockstep, fly at
    most this many simulated seconds per wall second (None: as fast as the CPU allows), so that
    a test acting from outside at a phase (a kill, a pilot) has a known margin.
    rangefinder: a downward rangefinder (``[world.rangefinder]``): its ranges from the true
    position to the deck's top (over the deck) or the ground (d = 0), sent as DISTANCE_SENSOR
    ``latency_s`` after capture (seeded by ``faults.seed``); None: none.
    """

    bind: str = "127.0.0.1:0"
    target: str | None = "127.0.0.1:14540"
    gcs_target: str | None = None
    gcs_bind: str = "127.0.0.1:0"
    speed: float = 1.0
    sysid: int = 1
    compid: int = 1
    home: tuple[float, float, float] = (47.397742, 8.545594, 488.0)
    start_ned: tuple[float, float, float] = (0.0, 0.0, 0.0)
    params: dict[str, float] = field(default_factory=dict)
    faults: FaultOptions = field(default_factory=FaultOptions)
    signing_key: bytes | None = None
    wind_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    position_noise_m: float = 0.0
    estimate_error: float = PX4_SITL_SCALE  # [-] x PX4 SITL's estimate errors (sim.vehicle.estimator); 0: exact (docs/mock-vehicle.md)
    statustext_needs_heartbeat: bool = True
    frame: str = "quadrotor"  # or "rover": MAV_TYPE_GROUND_ROVER, Ackermann kinematics (sim.vehicle.physics.rover)
    deck: DeckSpec | None = None
    lockstep: bool = False
    lockstep_watchdog_wall_s: float = 10.0  # mission.time.clock.VEHICLE_WATCHDOG_WALL_S
    lockstep_max_speed: float | None = None
    rangefinder: RangefinderSection | None = None  # a downward rangefinder sent as DISTANCE_SENSOR (sim.vehicle.physics.rangefinder)
    passenger_gnss: PassengerGnssSection | None = None  # a slow GNSS bias on a quadrotor's estimate (sim.vehicle.estimator.BiasedEstimateError)

    def __post_init__(self) -> None:
        if not self.speed > 0:
            raise ValueError(f"speed must be > 0, got {self.speed!r}")
        if not 1 <= self.sysid <= 255 or not 1 <= self.compid <= 255:
            raise ValueError(f"sysid and compid must be in 1..255, got {self.sysid}, {self.compid}")
        if self.signing_key is not None and len(self.signing_key) != 32:
            raise ValueError(f"signing_key must be 32 bytes, got {len(self.signing_key)}")
        if not self.estimate_error >= 0:
            raise ValueError(f"estimate_error must be >= 0, got {self.estimate_error!r}")
        if self.lockstep_max_speed is not None and not self.lockstep_max_speed > 0:
            raise ValueError(f"lockstep_max_speed must be > 0, got {self.lockstep_max_speed!r}")
        if not self.lockstep_watchdog_wall_s > 0:
            raise ValueError(f"lockstep_watchdog_wall_s must be > 0, got {self.lockstep_watchdog_wall_s!r}")
        if self.frame not in FRAMES:
            raise ValueError(f"frame must be one of {sorted(FRAMES)}, got {self.frame!r}")


@dataclass(frozen=True)
class VehicleSnapshot:
    """The vehicle's true state at simulated time ``t_s`` [s] (read-only arrays, NED)."""

    t_s: float
    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    yaw_rad: float
    armed: bool
    mode: str
    landed_state: int
    in_failsafe: bool
    position_valid: bool
    home_ned_m: np.ndarray
    last_setpoint_t_s: float
    counters: dict[str, int]
    setpoint: TrajectorySetpoint | None = None  # the last offboard setpoint accepted, as decoded
    battery_pct: float | None = None  # battery remaining [%] as reported (None: not simulated, SIM_BAT_ENABLE 0)
    on_deck: bool = False  # standing (or lying, crashed) on the carrier's deck, carried with it
    crash: str | None = None  # why the vehicle crashed on the deck (None: it has not)
    touchdowns: tuple[Touchdown, ...] = ()  # every contact with the deck, in order


def status_line(s: VehicleSnapshot) -> str:
    """One line for the log: time, mode, position and the counters that reveal trouble."""
    c = s.counters
    n, e, d = s.position_ned_m
    return (f"t={s.t_s:.1f}s {s.mode} {'ARMED' if s.armed else 'disarmed'}{' FAILSAFE' if s.in_failsafe else ''} "
            f"{'CRASHED ' if s.crash else 'ON_DECK ' if s.on_deck else ''}ned=({n:.1f},{e:.1f},{d:.1f}) rx={c['rx_messages']} "
            f"malformed={c['rx_malformed']} unknown_ids={c['rx_unknown_ids']} unsigned={c['rx_unsigned_rejected']} "
            f"wrong_target={c['rx_wrong_target']} sp={c['setpoints_accepted']}/{c['setpoints_rejected']}rej "
            f"tx={c['tx_messages']} drop_in={c['dropped_in'] + c['blackout_in']} "
            f"drop_out={c['dropped_out'] + c['blackout_out']}")


def frozen(values: Sequence[float]) -> np.ndarray:
    array = np.array(values, dtype=float)
    array.flags.writeable = False
    return array
