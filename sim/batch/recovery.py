"""Monte-Carlo of the recovery: whole missions flown in-process, the mission's own phase machine
against the mock vehicle's own dynamics and a kinematic carrier (no sockets, threads or clocks).

One scenario (:func:`fly`) is a whole mission of a ``final_action = "return"`` configuration,
deploy, task, return and dock, ticked as the lockstep demo ticks it:

- the passenger: the controller's own step (:class:`mission.passenger.step.PassengerStep`) every
  ``1 / mission.rate_hz`` [s], on what the controller reads in lockstep (the vehicle's reported
  position and velocity sampled at the tick, the carrier's newest state with its age, the
  readings of the world's measurement sensors, :mod:`sim.batch.sensors`); its setpoint goes to
  the vehicle at once, its
  requests (arm, OFFBOARD, Hold, Land) are carried out at once;
- the vehicle: the mock's commander (:class:`sim.vehicle.modes.Commander`) and PX4's position
  controller on the fitted airframe (:func:`sim.vehicle.physics.multicopter.step`) in the mock's
  fixed physics steps, the setpoint decoded by the mock's own MAVLink rules; optionally the
  errors of PX4's estimate (:mod:`sim.vehicle.estimator`), seeded;
- the carrier: the built-in kinematic robot (holonomic, the ``sim`` backend's
  :class:`mission.carrier.backends.sim.KinematicRobot`) at ``carrier.rate_hz``, driven by
  ``marsupial carrier``'s own step (:class:`mission.carrier.step.CarrierStepper`: its mode
  machine, legs, law, recovery course and P3 guards, with the ``sim`` backend's parameters):
  APPROACHING the paper's law towards the leg's target, filtered; RECOVERING the scenario's
  steady course (speed, heading), with its turn during the first approach, or, for a scenario
  ``configured``, the configuration's recovery course as ``marsupial carrier`` drives it;
  REPOSITIONING (several targets) straight out from the next leg's target; otherwise it stops.
  Every command passes the P3 guard of every target. It sees the status of the tick before.

A :class:`Scenario` is replayable from its fields (the seed only drives the estimate's errors);
:mod:`sim.batch.recovery_mc` draws them, flies a batch and reports it. The figures of each flight are those of the flight log's ``summary.json``
(:func:`mission.record.figures.summary_of` on the same columns). Frames: local NED [m], [m/s]; time [s]
from the start of the mission.
"""
from __future__ import annotations

import copy
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mission.core.records import replace
from mission.carrier.acceleration import AccelerationEstimate
from mission.carrier.backends.sim import KinematicRobot
from mission.carrier.frames import HeardBias
from mission.carrier.modes import CarrierMode, PassengerView
from mission.carrier.backends import OwnState
from mission.carrier.step import STOP, CarrierStepper
from mission.carrier.tracking import Tracked
from mission.config.schema import Config
from mission.errors import ConfigError
from mission.core.setpoint import Setpoint
from mission.core.tick import TickModel
from mission.flight_mode import FlightMode
from mission.phases.phase import Request
from mission.mavlink import setpoints
from mission.model import mission_model
from mission.interfaces import MeasurementSource
from mission.passenger.inputs import PassengerInputs, VehicleReport
from mission.passenger.relative import shared_bias
from mission.passenger.step import PassengerStep
from mission.phases import CarrierObs, Decision, Measurement, MissionState, Observation, Phase, finished
from mission.phases.phase import Duty
from mission.record.figures import summary_of
from mission.record.info import flown_info, mission_info
from mission.record.table import COLUMNS, VEC, FlightRecord
from sim.batch.sensors import SensorFactory, sensors_for
from sim.gnss import CarrierGnss, GnssFix
from mission.config.relnav import PassengerGnssSection
from sim.vehicle.estimator import BiasedEstimateError, EstimateError
from sim.vehicle.mock import PHYSICS_DT_S
from sim.vehicle.modes import Commander
from sim.vehicle.params import ParamTable, vehicle_limits
from sim.vehicle.physics.multicopter import initial_state, step as physics_step
from sim.vehicle.protocol import setpoint_of
from sim.vehicle.telemetry import PositionNoise

#: The mode each request of the phases switches to (as the controller's commands do).
MODES_OF_REQUEST = {Request.OFFBOARD: FlightMode.OFFBOARD, Request.HOLD: FlightMode.HOLD, Request.LAND: FlightMode.LAND}



@dataclass(frozen=True)
class Scenario:
    """One recovery: the carrier's recovery course ``speed_m_s`` [m/s] on ``heading_deg`` [deg]
    (NED: 0 north, 90 east), and its turn of ``turn_deg`` [deg] (signed, clockwise positive) at
    ``turn_rate_deg_s`` [deg/s] that begins ``turn_after_s`` [s] after the first approach
    began; ``estimate_error`` the vehicle's estimate errors as a multiple of PX4 SITL's (0: exact), seeded
    by ``seed``. ``index``: its place in its batch (the same seed gives the same batch).
    ``configured``: the carrier drives the configuration's own recovery course instead
    (``carrier.recovery_course``, ``recovery_heading_deg``, ``recovery_speed_m_s``; :func:`configured`)."""

    speed_m_s: float
    heading_deg: float
    turn_deg: float = 0.0
    turn_rate_deg_s: float = 10.0
    turn_after_s: float = 0.0
    estimate_error: float = 0.0
    seed: int = 0
    index: int = 0
    configured: bool = False  # the carrier drives the configured recovery course (carrier.recovery_*), not this one

    def course_heading_deg(self, since_approach_s: float | None) -> float:
        """The course's heading [deg] ``since_approach_s`` [s] after the first approach began (None: not yet)."""
        if since_approach_s is None or since_approach_s <= self.turn_after_s:
            return self.heading_deg
        turned = min(abs(self.turn_deg), self.turn_rate_deg_s * (since_approach_s - self.turn_after_s))
        return self.heading_deg + math.copysign(turned, self.turn_deg)

    def as_dict(self) -> dict[str, float]:
        return {"index": self.index, "speed_m_s": round(self.speed_m_s, 3), "heading_deg": round(self.heading_deg, 1),
                "turn_deg": round(self.turn_deg, 1), "turn_rate_deg_s": round(self.turn_rate_deg_s, 1),
                "turn_after_s": round(self.turn_after_s, 2), "estimate_error": self.estimate_error,
                "seed": self.seed}


def configured(estimate_error: float = 0.0, seed: int = 0) -> Scenario:
    """The mission as configured: the carrier drives the configuration's recovery course."""
    return Scenario(0.0, 0.0, estimate_error=estimate_error, seed=seed, configured=True)


# ---------------------------------------------------------------------------------------- carrier


def sim_backend(cfg: Config) -> Config:
    """``cfg`` as the carrier of this simulation sees it: driving the built-in robot
    (``carrier.backend = "sim"``), whose declared properties (it obeys at once: the P3 guard's
    default response delay is 0; it does not brake itself) set the step's parameters."""
    if cfg.carrier.backend == "sim":
        return cfg
    return cfg.model_copy(update={"carrier": cfg.carrier.model_copy(update={"backend": "sim"})})


class KinematicCarrier:
    """The built-in holonomic carrier robot (:class:`mission.carrier.backends.sim.KinematicRobot`)
    driven by the step of ``marsupial carrier`` (:class:`mission.carrier.step.CarrierStepper`, as
    :mod:`mission.carrier.controller` drives it with the ``sim`` backend): position [m], velocity
    [m/s] NED in the plane of ``scenario.carrier_start``; yaw [rad] the heading of travel. What
    the simulation adds is the world: the passenger's phase and leg it hears, and the scenario's
    drawn recovery course in place of the configured one (unless ``scenario.configured``)."""

    def __init__(self, cfg: Config, scenario: Scenario) -> None:
        if cfg.carrier.kinematics != "holonomic":
            raise ConfigError("carrier.kinematics", cfg.carrier.kinematics, "the mission simulation "
                              "drives the built-in holonomic carrier: must be \"holonomic\" to simulate it")
        if cfg.scenario.carrier_mode != "stop":
            raise ConfigError("scenario.carrier_mode", cfg.scenario.carrier_mode, "the mission simulation "
                              "drives a carrier that stops once the passenger has left: must be \"stop\" "
                              "to simulate it")
        self.cfg, self.scenario = cfg, scenario
        own = sim_backend(cfg)
        self.robot = KinematicRobot(own)
        self.stepper = CarrierStepper(own, self.robot.brakes_itself)
        self.period_s = 1.0 / cfg.carrier.rate_hz
        self.t_s = 0.0  # [s] the time of its state (its last step)
        self.done = 0  # steps taken (the next is at done * period_s)
        self.course_begun = False  # it has driven the scenario's recovery course
        # [world.carrier_gnss] enabled: it steers on and publishes its GNSS fixes, with their errors, as the
        # flight's carrier does (sim.gnss.ErringCarrier)
        self.gnss = CarrierGnss(cfg.world.carrier_gnss) if cfg.world.carrier_gnss.enabled else None
        self.fix: GnssFix | None = None  # the newest GNSS fix published so far, in its plane (_newest_fix)
        # carrier.acceleration_tau_s > 0: it sends its measured acceleration, as the controller does
        # (of its robot's own velocity: mission.carrier.acceleration.inertial_sample)
        tau = cfg.carrier.acceleration_tau_s
        self.acceleration = AccelerationEstimate(tau) if tau > 0 else None

    @property
    def model(self) -> TickModel:
        """The tick model of the leg the carrier serves."""
        return self.stepper.model

    @property
    def mode(self) -> CarrierMode:
        return self.stepper.mode

    @property
    def position(self) -> np.ndarray:
        """[m] NED (3,)."""
        return self.robot.position_m

    @property
    def velocity(self) -> np.ndarray:
        """[m/s] NED (3,): the command it holds."""
        return self.robot.velocity_m_s

    @property
    def yaw_rad(self) -> float:
        return self.robot.yaw_rad

    def next_step_s(self) -> float:
        """When [s] it steps next (every ``1 / carrier.rate_hz`` from 0)."""
        return self.done * self.period_s

    def step(self, phase: Phase | None, approach_s: float | None, leg: int = 0, bias: HeardBias | None = None) -> Tracked:
        """Step at :meth:`next_step_s`: move there under the held command, then decide the next
        command (returned, and held) for the passenger's ``phase`` (None: none heard yet) on its
        ``leg`` (the index of its target) and the frames' ``bias`` its status shares (relnav's, for the P3
        guard's frame; None: none); ``approach_s`` [s]: when the first approach began (None: not yet)."""
        t_s = self.next_step_s()
        dt = t_s - self.t_s
        self.robot.advance(dt)
        self.t_s = t_s
        self.done += 1
        self.stepper.update_mode(PassengerView(phase, separated=phase is not None and phase.separated, leg=leg,
                                               bias=bias))
        course: np.ndarray | None = None  # the scenario's course (None: the configured one)
        if self.mode is CarrierMode.RECOVERING:
            self.course_begun = True
            if not self.scenario.configured:
                course = self._scenario_course(t_s, approach_s)
        state, age = self._own_state(t_s)
        if state is None or age > self.cfg.carrier.state_timeout_s:  # the controller's stop without an own state
            self.stepper.hold()
            self.robot.command(STOP)
            if self.acceleration is not None:
                self.acceleration.reset()
            return STOP
        cmd = self.stepper.decide(state, dt, age, t_s, course).tracked
        self.robot.command(cmd)
        # the robot now holds the new command (the controller's order); the step at 0 is none of the
        # controller's (its first tick comes one period later, its first sample of the velocity)
        if self.acceleration is not None and self.done > 1:
            self.acceleration.update(t_s, self.robot.state_at(t_s).velocity_ned_m_s)
        return cmd

    def _own_state(self, t_s: float) -> tuple[OwnState | None, float]:
        """What it steers on at ``t_s`` [s] and how old that is [s]: its robot's state; with
        ``world.carrier_gnss.enabled`` the newest GNSS fix published by then, its robot's state as
        the inertial one (:class:`sim.gnss.ErringCarrier`'s; the heading its robot's own: the
        holonomic carrier does not steer by it). Before, it steered on its truth while the flight's
        carrier steered on its fixes, metres apart."""
        truth = self.robot.state_at(t_s)
        if self.gnss is None:
            return truth, 0.0
        fix = self._newest_fix(t_s)
        if fix is None:
            return None, math.inf
        return OwnState(fix.t_s, fix.position_ned_m, fix.velocity_ned_m_s, truth.yaw_rad,
                        inertial=truth), max(t_s - fix.t_s, 0.0)

    def _newest_fix(self, t_s: float) -> GnssFix | None:
        """The newest GNSS fix published by ``t_s`` [s] (None before the first), in the plane of
        ``scenario.carrier_start`` for a planar carrier in 3D, as the controller uses and publishes
        it (``CarrierController._in_plane``: a ground robot's height is not its fix's)."""
        assert self.gnss is not None
        published = self.gnss.observe(t_s, *self.true_at(t_s))
        newest = max(published, key=lambda f: f.t_s) if published else None
        if newest is not None and (self.fix is None or newest.t_s > self.fix.t_s):  # flattened once, as it comes
            p, v = newest.position_ned_m.copy(), newest.velocity_ned_m_s.copy()
            if self.stepper.planar and self.stepper.dim == 3:
                p[2], v[2] = self.cfg.scenario.carrier_start[2], 0.0
            self.fix = replace(newest, position_ned_m=p, velocity_ned_m_s=v)
        return self.fix

    def _scenario_course(self, t_s: float, approach_s: float | None) -> np.ndarray:
        """The scenario's recovery course's velocity [m/s] NED at ``t_s`` [s] (its turn during the
        first approach, which began at ``approach_s``)."""
        sc = self.scenario
        heading = math.radians(sc.course_heading_deg(None if approach_s is None else t_s - approach_s))
        return sc.speed_m_s * np.array([math.cos(heading), math.sin(heading), 0.0])

    def true_at(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Its true position [m] and velocity [m/s] NED at ``t_s`` [s] (moving on under the held command)."""
        return self.position + self.velocity * max(t_s - self.t_s, 0.0), self.velocity.copy()

    def observed(self, t_s: float) -> CarrierObs | None:
        """The newest published state as the passenger sees it at ``t_s`` [s]: with
        ``world.carrier_gnss.enabled`` the newest GNSS fix published by then (:class:`sim.gnss.CarrierGnss`,
        None before the first), else its state."""
        if self.gnss is not None:
            fix = self._newest_fix(t_s)
            if fix is None:
                return None
            return CarrierObs(position_ned_m=fix.position_ned_m.copy(), velocity_ned_m_s=fix.velocity_ned_m_s.copy(),
                              age_s=max(t_s - fix.t_s, 0.0), alive=True, yaw_rad=self.gnss.heading(self.yaw_rad),
                              acceleration_ned_m_s2=self._sent_acceleration())
        return CarrierObs(position_ned_m=self.position.copy(), velocity_ned_m_s=self.velocity.copy(),
                          age_s=max(t_s - self.t_s, 0.0), alive=True, yaw_rad=self.yaw_rad,
                          acceleration_ned_m_s2=self._sent_acceleration())

    def _sent_acceleration(self) -> np.ndarray | None:
        """The acceleration [m/s^2] NED it sends (None: none, ``carrier.acceleration_tau_s`` 0, or
        fewer than two steps yet)."""
        a = None if self.acceleration is None else self.acceleration.value
        return None if a is None else a.copy()


# ---------------------------------------------------------------------------------------- vehicle


class MockDynamics:
    """The mock vehicle without its sockets: the commander and the physics of
    :class:`sim.vehicle.mock.MockVehicle`, stepped in its fixed physics steps (its
    ``_advance_steps``), the estimate's errors when asked; what it reports is the estimate."""

    def __init__(self, start_ned_m: Sequence[float], estimate_error: float = 0.0, seed: int = 0,
                 params: dict[str, float] | None = None, gnss: PassengerGnssSection | None = None) -> None:
        self.kin = initial_state(tuple(float(x) for x in start_ned_m))  # type: ignore[arg-type]
        self.params = ParamTable(dict(params or {}), 1)
        self.limits = vehicle_limits(self.params)
        self.commander = Commander(self.params, self.kin)
        self.drift: EstimateError | None = EstimateError(estimate_error, seed=seed) if estimate_error > 0 else None
        if gnss is not None and gnss.bias_sigma_m > 0:  # [world.passenger_gnss]: its estimate's own GNSS bias
            self.drift = BiasedEstimateError(estimate_error, gnss, seed=seed)
        self.noise = PositionNoise(0.0, seed, self.drift)
        self.steps = 0
        self.wind = (0.0, 0.0, 0.0)

    def advance_to_step(self, target: int) -> None:
        """Run the commander and the physics up to physics step ``target``."""
        commander, kin, limits, drift = self.commander, self.kin, self.limits, self.drift
        for k in range(self.steps + 1, target + 1):
            command = commander.step(k * PHYSICS_DT_S, kin)
            if drift is not None:  # PX4's controller flies its estimate (sim.vehicle.estimator)
                drift.advance(PHYSICS_DT_S, commander.taken_off)
                kin = physics_step(kin, command, limits, self.wind, PHYSICS_DT_S, (drift.position, drift.velocity))
            else:
                kin = physics_step(kin, command, limits, self.wind, PHYSICS_DT_S)
        self.steps = max(self.steps, target)
        self.kin = commander.kin = kin

    def report(self, t_s: float) -> VehicleReport:
        """The vehicle as the controller's link reports it at ``t_s`` [s] in lockstep: its reported
        (estimated) position and velocity, sampled and received at ``t_s``, a HEARTBEAT just heard."""
        k, c = self.kin, self.commander
        return VehicleReport(t_s=t_s, position_ned_m=np.array(self.noise.apply(k)),
                             velocity_ned_m_s=np.array(self.noise.velocity(k)), sample_t_s=t_s, rx_s=t_s, armed=c.armed,
                             mode=c.mode, heartbeat_age_s=0.0, valid=c.position_valid, in_failsafe=c.in_failsafe)

    def send(self, t_s: float, sp: Setpoint) -> None:
        """The setpoint through the one MAVLink encoding and the mock's decoding rules."""
        trajectory, reason = setpoint_of(setpoints.encode(sp, (1, 1), int(t_s * 1000)), self.kin.yaw_rad)
        if trajectory is None:
            self.commander.reject_setpoint(t_s, reason)
        else:
            self.commander.accept_setpoint(t_s, trajectory)

    def request(self, t_s: float, request: Request) -> str | None:
        """Carry out a request; the vehicle's refusal (its STATUSTEXT), or None when accepted."""
        c = self.commander
        before = len(c.outbox)
        result = c.arm(t_s) if request is Request.ARM else c.set_mode(t_s, MODES_OF_REQUEST[request])
        return None if result == 0 else (c.outbox[-1][2] if len(c.outbox) > before else f"MAV_RESULT {result}")

    def carry_out(self, t_s: float, dec: Decision, failed: dict[str, str]) -> None:
        """The passenger step's decision at ``t_s`` [s]: its setpoint sent, its request carried out
        unless it failed before (``failed``: request -> the vehicle's refusal, kept for the step,
        as the flight's command worker keeps an ARM or OFFBOARD the vehicle refused)."""
        if dec.setpoint is not None:
            self.send(t_s, dec.setpoint)
        if dec.request is not None and dec.request.value not in failed:
            why = self.request(t_s, dec.request)
            if why is not None and dec.request in (Request.ARM, Request.OFFBOARD):
                failed[dec.request.value] = why

    @property
    def true_position(self) -> np.ndarray:
        return np.array((self.kin.n_m, self.kin.e_m, self.kin.d_m))


# ----------------------------------------------------------------------------------------- flight


@dataclass
class Flight:
    """One flown scenario: ``record`` the flight record (the columns of record.csv, plus
    ``x_true`` the vehicle's true position [m] and ``course`` the recovery's view of the
    carrier's course); ``summary`` what summary.json would say; ``state`` the phase machine's
    last state; ``true_deck_violations`` the deck violations counted on the true position;
    ``events`` (t [s], text) what the phases said (the flight log's lines)."""

    scenario: Scenario
    record: FlightRecord
    summary: dict[str, Any]
    state: MissionState
    true_deck_violations: int = 0
    events: list[tuple[float, str]] = field(default_factory=list)

    @property
    def go_arounds(self) -> list[str]:
        """Why each go-around began."""
        return [text.removeprefix("go-around: ") for _, text in self.events if text.startswith("go-around: ")]

    @property
    def docked(self) -> bool:
        """It docked again (with several targets: after every leg, the leg it was on included: a
        mission that ended riding on to a leg it never flew did not, its summary's leg having no
        contact of its own, :mod:`mission.record.figures`)."""
        legs = self.summary.get("legs")
        if legs:
            return all(leg.get("contact") is not None for leg in legs)
        return bool(self.summary.get("docked_again"))

    @property
    def attempts(self) -> int:
        """The approaches its recovery took (with several targets: the most any leg's took)."""
        rec = self.state.recovery
        done = [leg["contact"]["attempts"] for leg in self.state.legs_done if leg.get("contact")]
        return max([0 if rec is None else rec.attempts, *done])


@dataclass
class _Rows:
    """The flight record's columns as the loop appends them."""

    t: list[float] = field(default_factory=list)
    phase: list[str] = field(default_factory=list)
    vecs: dict[str, list[np.ndarray]] = field(default_factory=dict)

    def add(self, t: float, phase: Phase, **vecs: np.ndarray | None) -> None:
        self.t.append(t)
        self.phase.append(phase.value)
        for name, v in vecs.items():
            self.vecs.setdefault(name, []).append(np.full(3, np.nan) if v is None else np.asarray(v, dtype=float))

    def record(self, info: dict[str, Any]) -> FlightRecord:
        cols: dict[str, np.ndarray] = {"t_s": np.asarray(self.t)}
        for name, rows in self.vecs.items():
            arr = np.asarray(rows, dtype=float).reshape(-1, 3)
            for i, a in enumerate(VEC):
                cols[f"{name}_{a}"] = arr[:, i]
        for name in COLUMNS:  # the scalar columns the summary does not read
            cols.setdefault(name, np.full(len(self.t), np.nan))
        return FlightRecord(t=np.asarray(self.t), phase=np.asarray(self.phase, dtype=str), cols=cols, info=info)


def as_simulated(cfg: Config) -> Config:
    """``cfg`` if this simulation can fly it; raises :class:`ConfigError` for ``mission.ride =
    "deck"``: its mock dynamics have no deck (the vehicle cannot sit on the carrier, disarmed, and
    take off from it), and hover riding on a deck-height dock point is another mission."""
    if cfg.mission.ride == "deck":
        raise ConfigError("mission.ride", cfg.mission.ride, "the simulation has no deck: fly the deck ride with "
                          "`marsupial demo` (the mock vehicle rides the carrier's deck), or simulate a copy that "
                          "rides hovering (mission.ride = \"hover\", the dock point above the deck)")
    return cfg


class World:
    """A mission in flight: the phase machine's state, the vehicle, the carrier and the record so
    far; :meth:`tick` advances it by one controller tick. :meth:`copy` branches it: the flights
    of a batch share the part before the recovery (:func:`monte_carlo`). ``sensors``: the
    world's measurement sensors (:mod:`sim.batch.sensors`; default: those of the feeds
    ``mission.feeds`` names), polled every tick like the flight loop's feeds."""

    def __init__(self, cfg: Config, scenario: Scenario, max_duration_s: float | None = None,
                 sensors: Sequence[SensorFactory] | None = None) -> None:
        cfg = as_simulated(cfg)
        self.cfg, self.model = cfg, mission_model(cfg)
        self.dt_s = self.model.dt_s
        self.steps_per_tick = int(round(self.dt_s / PHYSICS_DT_S))
        if abs(self.steps_per_tick * PHYSICS_DT_S - self.dt_s) > 1e-12:
            raise ConfigError("mission.rate_hz", cfg.mission.rate_hz,
                              f"must divide the mock's physics rate ({1 / PHYSICS_DT_S:g} Hz) to simulate the mission")
        self.vehicle = MockDynamics(cfg.scenario.carrier_start, scenario.estimate_error, scenario.seed,
                                    gnss=cfg.world.passenger_gnss)
        self.carrier = KinematicCarrier(cfg, scenario)
        self.state = MissionState()
        self.rows = _Rows()
        self.published: Phase | None = None  # the status the carrier hears: the phase and its leg
        self.published_leg = 0
        self.published_bias: HeardBias | None = None  # the frames' bias the status shares (relnav's)
        self.approach_s: float | None = None  # when the first approach began [s]
        self.failed: dict[str, str] = {}
        self.events: list[tuple[float, str]] = []  # (t [s], what the phases said)
        self.step = PassengerStep(self.model, cfg.mission.velocity_bias_tau_s,  # the controller's own step
                                  cfg.mission.near_deck_velocity_bias_tau_s)
        self.limit_s = max_duration_s if max_duration_s is not None else self.model.max_duration_s + 30.0
        self.k = 0
        self.done = False
        self.sources: list[MeasurementSource] = [make(self) for make in (sensors_for(cfg) if sensors is None else sensors)]

    @property
    def scenario(self) -> Scenario:
        return self.carrier.scenario

    def copy(self) -> World:
        """An independent copy (the configuration, the model and the vehicle's parameters,
        which never change in flight, shared)."""
        shared = (self.cfg, self.model, self.vehicle.params, self.vehicle.limits)
        return copy.deepcopy(self, memo={id(x): x for x in shared})

    def with_scenario(self, scenario: Scenario) -> World:
        """This world flying ``scenario`` from now on; only before the carrier drives its recovery
        course, and with the same estimate (what differs between scenarios)."""
        if self.carrier.course_begun or scenario.estimate_error != self.scenario.estimate_error \
                or (scenario.estimate_error > 0 and scenario.seed != self.scenario.seed):
            raise ValueError("a world takes another scenario only before the recovery, with the same estimate")
        self.carrier.scenario = scenario
        return self

    def tick(self) -> None:
        """One controller tick at ``k * dt``: the carrier's steps due, the vehicle brought to the
        tick, the sensors polled, the phase machine, its setpoint and request carried out, the row
        recorded."""
        t = self.k * self.dt_s
        carrier, vehicle = self.carrier, self.vehicle
        while carrier.next_step_s() <= t + 1e-9:  # the carrier steps first, on the status of the tick before
            carrier.step(self.published, self.approach_s, self.published_leg, self.published_bias)
        vehicle.advance_to_step(self.k * self.steps_per_tick)
        measured: tuple[Measurement, ...] = tuple(m for source in self.sources for m in source.poll(t))
        result = self.step(self.state, PassengerInputs(t, vehicle.report(t), carrier.observed(t), dict(self.failed),
                                                       measurements=measured))
        self.state, obs, dec = result.state, result.observation, result.decision
        vehicle.carry_out(t, dec, self.failed)
        self.events.extend((t, text) for text in dec.events)
        self.published, self.published_leg = self.state.phase, self.state.leg
        shared = shared_bias(obs.relative)  # as the controller's status shares it, heard at the carrier's next step
        self.published_bias = None if shared is None else HeardBias(*shared, t, 0.0)
        if self.approach_s is None and self.state.phase is Phase.APPROACH:
            self.approach_s = t
        _record(self.rows, t, self.state, obs, dec, vehicle, carrier)
        self.k += 1
        self.done = finished(self.state, dec) or t >= self.limit_s

    def run(self, until: Callable[[World], bool] | None = None) -> World:
        """Tick until the mission ends (or ``until(self)`` holds)."""
        while not self.done and not (until is not None and until(self)):
            self.tick()
        return self

    def flight(self) -> Flight:
        """The flight so far, with its summary."""
        st = self.state
        info = {**mission_info(self.cfg), **flown_info(st)}
        record = self.rows.record(info)
        summary = summary_of(record)
        summary.update(phase=st.phase.value, reason=None if st.reason is None else st.reason.value, detail=st.detail,
                       ticks=self.k)
        true = summary_of(replace(record, cols={**record.cols, **{f"x_p_{a}": record.cols[f"x_true_{a}"] for a in VEC}}))
        return Flight(self.scenario, record, summary, st, int(true.get("deck_violations") or 0), list(self.events))


def fly(cfg: Config, scenario: Scenario, max_duration_s: float | None = None) -> Flight:
    """Fly one whole mission of ``cfg`` (``mission.final_action = "return"``) in ``scenario``."""
    return World(cfg, scenario, max_duration_s).run().flight()


def before_recovery(cfg: Config, estimate_error: float = 0.0, seed: int = 0) -> World:
    """The mission flown up to the first tick of its recovery (the carrier not yet told): what
    every scenario with this estimate shares."""
    return World(cfg, Scenario(0.0, 0.0, estimate_error=estimate_error, seed=seed)).run(
        lambda w: w.published is not None and w.published.duty is Duty.RECOVER)


def _record(rows: _Rows, t: float, state: MissionState, obs: Observation, dec: Decision, vehicle: MockDynamics,
            carrier: KinematicCarrier) -> None:
    v, c = obs.vehicle, obs.carrier
    rec = state.recovery
    deck_true = carrier.true_at(t)[0]
    rel = obs.relative
    rows.add(t, state.phase, x_c_true=deck_true, rel_true=deck_true - vehicle.true_position,
             rel_est=None if rel is None else rel.position_ned_m, bias_est=None if rel is None else rel.bias_ned_m,
             since_marker=None if rel is None else np.full(3, rel.since_marker_s), x_p=None if v is None else v.position_ned_m, v_p=None if v is None else v.velocity_ned_m_s,
             x_c=None if c is None else c.position_ned_m, v_c=None if c is None else c.velocity_ned_m_s, dock=dec.dock,
             x_ref=state.x_ref, u_cmd=None if dec.setpoint is None else dec.setpoint.velocity_ned_m_s,
             x_true=vehicle.true_position, course=None if rec is None else rec.course)


def draw(flight: Flight, path: str | Path, what: str) -> Path | None:
    """The flight's recovery figure (:func:`mission.plots.plot_recovery`) at ``path``, titled
    ``what`` and its scenario; None when it never began its recovery."""
    from mission.plots import plot_recovery, recovery_track

    sc = flight.scenario
    track = recovery_track(flight.record, f"{what}: carrier {sc.speed_m_s:.2f} m/s on {sc.heading_deg:.0f} deg, turn "
                           f"{sc.turn_deg:+.0f} deg at {sc.turn_rate_deg_s:.0f} deg/s {sc.turn_after_s:.1f} s into the "
                           f"first approach")
    return None if track is None else plot_recovery(track, path)
