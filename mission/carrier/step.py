"""One step of the carrier (pure: no clock, no I/O, no log): its mode from the passenger's view,
and the command for its own state.

``marsupial carrier`` (:class:`mission.carrier.controller.CarrierController`: the backend, the
bus, the deck alignment, the log, the accounting) and the in-process recovery simulation
(:class:`sim.batch.recovery.KinematicCarrier`: the built-in robot's kinematics) drive their
carrier with the same :class:`CarrierStepper`, built from the configuration by the same
functions (:func:`carrier_model`, :func:`guard_params`, :func:`tracking_params`) and the
backend's declared properties: its kind's ``real`` (:data:`mission.config.carrier.KINDS`) sets
the guard's default response delay, its ``brakes_itself`` whether a stop is sent at once or
ramped down by the law's acceleration limit.

One step, every ``1 / carrier.rate_hz`` [s]:

1. :meth:`CarrierStepper.update_mode`: the passenger's leg is followed (forward only,
   :class:`~mission.carrier.legs.Legs`) while it rides or rides on, then the mode machine
   (:func:`~mission.carrier.modes.next_mode`). Entering SEPARATED fixes the carrier's own plan
   (Remark 1): the law's command of that instant after an approach, zero otherwise (a recovery
   that falls back keeps the plan it had). Any mode but RECOVERING and PAUSED forgets the recovery
   course's start: the next recovery drives its course from its own start.
2. :meth:`CarrierStepper.decide`: a vehicle that brakes itself is sent a stop at once while the
   carrier stops; otherwise :func:`mission.core.tick.carrier_tick` at its position in the guards'
   frame (:mod:`mission.carrier.frames`: where the passenger has the targets) (the paper's law while
   approaching; once separated a stop or the own plan; RECOVERING the recovery course of
   :mod:`mission.carrier.course`, its clock and its away-from-the-target heading taken at its
   first step; REPOSITIONING the drive out to the next leg's start; CBF filter, speed and
   acceleration limits), sped up gently while the carrier stands (:mod:`mission.carrier.start`),
   then for a holonomic carrier the P3 guard of every target on the planar command and
   :func:`~mission.carrier.tracking.track`, for a diff-drive or Ackermann one
   :func:`~mission.carrier.tracking.track`, the guards along its heading and the speed
   calibration (:class:`~mission.carrier.tracking.SpeedCalibration`), then the correction for the
   vehicle's own speed loop (:func:`~mission.carrier.tracking.speed_loop_corrected`).

Frames: local NED [m], [m/s], in the scenario's dimension (2 or 3); times [s] of the caller's clock.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from mission.carrier.backends import OwnState
from mission.carrier.course import RecoveryCourse, away_heading_deg, clear_heading_deg
from mission.carrier.frames import FrameParams, GuardFrame
from mission.carrier.guard import AWAY_TURN_BAND_M, GuardParams
from mission.carrier.legs import TURN_ROOM_M, Legs
from mission.carrier.modes import CarrierMode, PassengerView, next_mode
from mission.carrier.start import MOVING_M_S, gentle_start, speed_lead
from mission.carrier.tracking import (SpeedCalibration, Tracked, TrackingParams, heading_of, own_speed_m_s,
                                      speed_loop_corrected, track)
from mission.config.carrier import KINDS
from mission.config.schema import Config
from mission.core.consistent_velocity import PositionConsistentVelocity
from mission.core.tick import ROUND_BAND_M, TickModel, carrier_tick
from mission.model import model_from_config
from mission.phases.phase import Duty

STOP = Tracked(0.0, 0.0, 0.0, np.zeros(2), np.zeros(2))
REAL_DELAY_S = 0.3  # [s] default response delay of a real carrier for the P3 guard (carrier.brake_delay_s)
RESTART_S = 1.0  # [s] the least a carrier with carrier.min_moving_speed_m_s stands once stopped (CarrierStepper._restarting)
DRIVING = (CarrierMode.APPROACHING, CarrierMode.RECOVERING, CarrierMode.REPOSITIONING)  # modes that drive on


def pad3(v: np.ndarray) -> np.ndarray:
    """A (2,) or (3,) vector as (3,) (a 2D scenario's carrier sits at down = 0)."""
    v = np.asarray(v, dtype=float)
    return np.concatenate([v, np.zeros(3 - v.shape[0])]) if v.shape[0] < 3 else v


def carrier_model(cfg: Config, target: np.ndarray | None = None) -> TickModel:
    """The tick model of the carrier: the config's (for ``target``, a leg's: default the first),
    with the carrier's speed limit ``min(carrier.max_speed_m_s, safety.carrier_max_speed_m_s)`` [m/s]."""
    model = model_from_config(cfg, target=target)
    limit = cfg.carrier.max_speed_m_s
    if model.carrier_safety.max_speed_m_s is not None:
        limit = min(limit, model.carrier_safety.max_speed_m_s)
    return dataclasses.replace(model, carrier_safety=dataclasses.replace(model.carrier_safety, max_speed_m_s=limit))


def guard_params(cfg: Config) -> GuardParams:
    """The P3 guard of ``cfg``: radius ``b c - carrier.p3_margin_m`` [m]; it plans with the
    carrier's response delay plus one control period (a command is held that long), and for a
    diff-drive or Ackermann carrier with its turning model (``carrier.turn_radius_m``, default
    the Ackermann geometry's ``wheelbase_m / tan(max_steer_rad)``, diff-drive 0;
    ``carrier.turn_reserve_m``)."""
    c = cfg.carrier
    decel = c.brake_decel_m_s2 or cfg.safety.carrier_max_accel_m_s2 or 1.0
    delay = c.brake_delay_s if c.brake_delay_s is not None else (REAL_DELAY_S if KINDS[c.backend].real else 0.0)
    turn: float | None = None
    if c.kinematics != "holonomic":
        turn = c.turn_radius_m if c.turn_radius_m is not None else (
            c.wheelbase_m / math.tan(c.max_steer_rad) if c.kinematics == "ackermann" else 0.0)
    return GuardParams(cfg.law.params().separation_distance_m - c.p3_margin_m, decel, delay, 1.0 / c.rate_hz,
                       turn_radius_m=turn, turn_reserve_m=c.turn_reserve_m)


def tracking_params(cfg: Config) -> TrackingParams:
    """What the carrier can follow (``carrier.kinematics`` and its tracking law's settings)."""
    c = cfg.carrier
    return TrackingParams(c.kinematics, c.heading_gain, c.max_yaw_rate_rad_s, c.min_speed_fraction, c.wheelbase_m,
                          c.max_steer_rad, c.speed_loop_correction)


@dataclass(frozen=True)
class ModeUpdate:
    """What :meth:`CarrierStepper.update_mode` did: the mode ``before`` and ``after`` it, why it
    changed (``""``: it did not), and whether the carrier took a later leg (``leg_changed``)."""

    before: CarrierMode
    after: CarrierMode
    why: str
    leg_changed: bool


@dataclass(frozen=True)
class Command:
    """What :meth:`CarrierStepper.decide` decided: ``tracked`` the command for the robot;
    ``guard_active`` the P3 guard cut it; ``feasible`` False when the CBF filter found no
    command (it holds still); ``frame_change`` what changed in the guard's frame, for the log
    (:meth:`mission.carrier.frames.GuardFrame.settle`; ``""``: nothing)."""

    tracked: Tracked
    guard_active: bool = False
    feasible: bool = True
    frame_change: str = ""


class CarrierStepper:
    """The carrier's mode, its law's last command and the memory of its guards, legs, recovery
    course and speed calibration, for ``cfg`` on a backend that ``brakes_itself`` or not (see
    the module docstring)."""

    def __init__(self, cfg: Config, brakes_itself: bool, dock_offsets_m: np.ndarray | None = None) -> None:
        c = cfg.carrier
        self.guard = guard_params(cfg)
        self.tracking = tracking_params(cfg)
        self.brakes_itself = brakes_itself
        self.dim = cfg.scenario.dim
        targets = [np.asarray(t, dtype=float) for t in cfg.scenario.legs()]
        first = carrier_model(cfg)
        self.planar = first.planar_carrier or self.dim == 2
        self.frame = GuardFrame(FrameParams.from_carrier(c), self.planar)  # the guards' frame (mission.carrier.frames)
        self.legs = Legs(targets, [carrier_model(cfg, target=t) for t in targets], self.guard, self.planar,
                         np.asarray(cfg.mission.dock_offset_ned_m if dock_offsets_m is None else dock_offsets_m,
                                    dtype=float)[..., :self.dim],
                         first.law.separation_distance_m + cfg.mission.leg_start_margin_m, self.frame)
        self.away_within_m = first.law.separation_distance_m + AWAY_TURN_BAND_M  # [m] turns round away from a target
        self.course = RecoveryCourse.from_lists(c.recovery_course, c.recovery_heading_deg, c.recovery_speed_m_s)
        self.start_accel_m_s2, self.start_lead_m_s = c.start_accel_m_s2, c.start_lead_m_s
        self.min_moving_speed_m_s, self.floor_from_m_s = c.min_moving_speed_m_s, max(c.floor_from_m_s, MOVING_M_S)
        # [m/s] its motion for the start's caps: the estimator's velocity made consistent with its position
        self._motion = PositionConsistentVelocity(c.start_motion_tau_s) if c.start_motion_tau_s > 0 else None
        self.mode = CarrierMode.WAITING
        self.velocity_m_s = np.zeros(self.dim)  # [m/s] the filtered (and, holonomic, guarded) law command
        self._plan_velocity = np.zeros(self.dim)  # [m/s] the own plan after separation (Remark 1)
        self._course_start: tuple[float, float] | None = None  # (time [s], away heading [deg]) of the recovery
        self._calibration = SpeedCalibration(c.speed_ratio_tau_s)
        self._asked_speed_m_s = 0.0  # [m/s] diff-drive/Ackermann: the forward speed last asked (before the guards)
        self._stopped_since_s: float | None = None  # [s] diff-drive/Ackermann: since when it is asked to stop
        self._ride_begins = False  # APPROACHING entered from driving on: its first step asks a stop if none was
        self._leg_turn = "out"  # REPOSITIONING, non-holonomic: "out", then "turn" towards the leg's target, "done"
        self.fix_smoothing_tau_s = c.fix_smoothing_tau_s
        self._navigated: tuple[float, np.ndarray] | None = None  # (fix time [s], smoothed position [m]) of the last fix

    @property
    def model(self) -> TickModel:
        """The tick model of the leg the carrier serves (its target is the law's)."""
        return self.legs.model

    def update_mode(self, view: PassengerView) -> ModeUpdate:
        """Follow the passenger's leg and take the mode after the current one given ``view``
        (and the frames' bias it shares, for the guards' frame)."""
        self.frame.hear(view.bias)
        leg_changed = (view.phase is not None and view.phase.duty in (Duty.REPOSITION, Duty.CARRY)
                       and self.legs.follow(view.leg))
        before = self.mode
        mode, why = next_mode(before, view)
        if mode is not before:
            if mode is CarrierMode.SEPARATED and before is not CarrierMode.RECOVERING:  # after a recovery: the same plan
                self._plan_velocity = (self.velocity_m_s.copy() if before is CarrierMode.APPROACHING
                                       else np.zeros_like(self.velocity_m_s))
            if mode not in (CarrierMode.RECOVERING, CarrierMode.PAUSED):
                self._course_start = None  # the next recovery drives its course from its own start
            if mode is CarrierMode.REPOSITIONING:
                self._leg_turn = "out"  # a new repositioning turns afresh
            self._ride_begins = mode is CarrierMode.APPROACHING and before in DRIVING
            self.mode = mode
        return ModeUpdate(before, mode, why, leg_changed)

    def hand_over(self, view: PassengerView) -> None:
        """The carrier serves another passenger of its team from now (:class:`mission.carrier.team.TeamCarrier`):
        its mode starts afresh for that passenger's ``view``, from the mode in which what that
        passenger's duty asks is a transition of :func:`~mission.carrier.modes.next_mode`
        (REPOSITION: from RECOVERING; anything else: from WAITING, so that a CARRY starts the
        approach only confirmed on the dock point). The law's command, the guards' memory and the
        own plan are kept: the command goes on from where it is, at the acceleration limit."""
        duty = view.phase.duty if view.phase is not None else Duty.WAIT
        self.mode = CarrierMode.RECOVERING if duty is Duty.REPOSITION else CarrierMode.WAITING
        self._course_start = None

    def stopping(self) -> bool:
        """A stop for good or for now: not driving (approaching, recovering, repositioning), and no
        own plan (Remark 1) to follow."""
        return self.mode not in DRIVING and not (self.mode is CarrierMode.SEPARATED
                                                 and self.model.carrier_mode == "remark1")

    def hold(self) -> None:
        """The carrier is sent a stop from outside the step (no own state, a fault): the law's
        command starts again from rest."""
        self.velocity_m_s = np.zeros(self.dim)
        self._asked_speed_m_s = 0.0

    def decide(self, state: OwnState, dt_s: float, age_s: float, now_s: float,
               recovery_velocity_m_s: np.ndarray | None = None) -> Command:
        """The command for the own ``state`` (measured ``age_s`` [s] ago), ``dt_s`` [s] after the
        last step, at ``now_s`` [s]. ``recovery_velocity_m_s`` [m/s] NED: a recovery course the
        caller drives instead of the configured one while RECOVERING (a simulation's drawn course)."""
        change = self.frame.settle(now_s)  # the guards' frame at this step
        state = self.navigated(state)
        x_c = state.position_ned_m[:self.dim]
        v_motion = self.motion_m_s(state)
        if self.stopping() and self.brakes_itself:
            # A real vehicle brakes with its own limits: ramping the command down at
            # safety.carrier_max_accel_m_s2 (the built-in robot's braking) would keep it driving.
            self.velocity_m_s = np.zeros(self.dim)
            self._asked_speed_m_s = 0.0
            self._stopped_since_s = now_s if self._stopped_since_s is None else self._stopped_since_s
            return Command(STOP, frame_change=change)
        separated = self.mode is not CarrierMode.APPROACHING
        plan = self._plan_velocity if self.mode is CarrierMode.SEPARATED else None
        res = carrier_tick(x_c - self.frame.shift_ned_m(self.dim, self.planar), separated, self.model,  # the guards' frame
                           own_plan_velocity=plan, u_prev=self.velocity_m_s,
                           dt_s=dt_s if dt_s > 0 else None,
                           course_velocity=self.course_velocity(x_c, now_s, recovery_velocity_m_s, state.yaw_rad))
        u = np.asarray(res.u, dtype=float)
        yaw = state.yaw_rad if state.yaw_rad is not None else 0.0
        t, v_meas = state.t_s, state.velocity_ned_m_s[:self.dim]
        # A carrier that stands speeds its command up gently until it moves (stiction: mission.carrier.start);
        # a robot that moves along its heading by its forward speed (its estimator's sideways wander is no motion)
        moving = own_speed_m_s(v_motion, state.yaw_rad, self.tracking.kind)
        active = False
        if self.tracking.kind == "holonomic":
            u = speed_lead(gentle_start(u, self.velocity_m_s, moving, self.start_accel_m_s2, dt_s), moving,
                           self.start_lead_m_s)
            for guard in self.legs.guards:  # every target is hazardous, whichever leg is flown
                g = guard.limit(t, x_c, u, v_meas, age_s)
                u, active = g.u, active or g.active
            cmd = track(u, yaw, self.tracking)
        else:
            ride_begins, self._ride_begins = self._ride_begins, False
            if ride_begins and self._stopped_since_s is None:  # a ride begins from a stand (_restarting)
                self._stopped_since_s = now_s
            if self._restarting(now_s):  # it stands on, and the law starts again from rest after
                u = np.zeros_like(u)
            sideways = abs(math.cos(yaw) * float(v_motion[1]) - math.sin(yaw) * float(v_motion[0]))
            bearing = math.atan2(float(u[1]), float(u[0]))  # round away from a target near it, not through it
            turn = next((w for g in self.legs.guards if (w := g.away_turn(x_c, yaw, bearing, self.away_within_m))), 0)
            cmd = self._started(u, yaw, moving, dt_s, sideways, turn)
            self._stopped_since_s = (None if cmd.speed_m_s > 0 else
                                     now_s if self._stopped_since_s is None else self._stopped_since_s)
            speed = cmd.speed_m_s
            for guard in self.legs.guards:
                speed, acted = guard.limit_heading(t, x_c, speed, yaw, v_meas, age_s, bearing_rad=cmd.bearing_rad)
                active = active or acted
            if active:
                scale = speed / cmd.speed_m_s if cmd.speed_m_s > 0 else 0.0
                cmd = Tracked(speed, cmd.yaw_rate_rad_s, cmd.bearing_rad, heading_of(speed, yaw),
                              cmd.setpoint_ned_m_s * scale)
            cmd = speed_loop_corrected(self._calibration.asked(cmd, yaw, v_meas, dt_s), state.yaw_rad, v_meas, v_motion,
                                       self.tracking, active)  # what to ask for so that it does ``cmd``
        # The law's planar command (not the motion along the heading) is what the acceleration limit and
        # Remark 1 act on: tying it to the heading would let it turn only as fast as the robot does (a heading lock).
        self.velocity_m_s = u
        return Command(cmd, active, bool(np.all(res.feasible)), change)

    def navigated(self, state: OwnState) -> OwnState:
        """The own state it steers and guards on: ``state`` itself, unless ``carrier.fix_smoothing_tau_s``
        > 0 and ``state`` is a GNSS fix with the robot's inertial state beside it
        (:attr:`OwnState.inertial`); then, at each new fix, the last smoothed position moved on by
        the inertial velocity [m/s] to the fix's time and pulled towards the fix by ``1 - exp(-dt /
        tau)``, with the inertial velocity (a rover's EKF: the fixes' bias stays, their noise of
        0.3 m and 0.2 m/s goes; one noisy fix tripped the P3 guard under a riding passenger,
        docs/relnav.md, "The carrier's law in its own frame")."""
        tau, inertial = self.fix_smoothing_tau_s, state.inertial
        if tau <= 0 or inertial is None:
            return state
        fix = np.asarray(state.position_ned_m, dtype=float)
        v = np.asarray(inertial.velocity_ned_m_s, dtype=float)
        if self._navigated is None:
            self._navigated = (state.t_s, fix.copy())
        elif state.t_s > self._navigated[0]:
            t0, x0 = self._navigated
            dt = state.t_s - t0
            predicted = x0 + v * dt
            self._navigated = (state.t_s, predicted + (1.0 - math.exp(-dt / tau)) * (fix - predicted))
        return OwnState(state.t_s, self._navigated[1].copy(), v.copy(), state.yaw_rad, inertial)

    def motion_m_s(self, state: OwnState) -> np.ndarray:
        """The velocity [m/s] NED (dim,) by which the start's caps (:meth:`_started`,
        :mod:`mission.carrier.start`) judge whether the carrier moves: with
        ``carrier.start_motion_tau_s`` > 0 the ``state``'s velocity made consistent with its
        position (:mod:`mission.core.consistent_velocity`; a sample no newer than the last changes
        nothing), else the estimator's velocity as it is. The guards and the speed calibration
        keep the estimator's.

        Why: at leg 2's start PX4's SIH rover stood still (its position's rate -0.05 to +0.03 m/s)
        while its EKF said -0.2 to -0.25 m/s forward or 0.2-0.36 m/s sideways, for 1-2 s after it
        braked out of its turn; read as moving, or as unsure, the speed asked ramped at the law's
        1 m/s^2 instead of the gentle start's 0.25, the rover stuck until asked 0.7-0.8 m/s, then
        leapt to 1.1-1.3 m/s in 0.5 s, and the riding passenger, whose command grows at 2 m/s^2,
        trailed 0.30-0.35 m (docs/recovery.md, "On real PX4")."""
        v = state.velocity_ned_m_s[:self.dim]
        if self._motion is None:
            return v
        return self._motion.update(state.t_s, state.position_ned_m[:self.dim], v)

    def _restarting(self, now_s: float) -> bool:
        """A diff-drive or Ackermann carrier with ``carrier.min_moving_speed_m_s`` that was last
        asked to stop less than :data:`RESTART_S` ago at ``now_s`` [s]: it stands on. PX4's rover
        holds a rest point once it stands (``carrier.mavlink.stand``), which resets its speed
        loop; asked to drive again the tick it stopped (leg 2's ride began as its turn towards
        target 2 ended), the SIH rover leapt to 1.9 m/s, 55 deg off its bearing, under the riding
        passenger (docs/recovery.md, "On real PX4"). A ride entered from driving on (:data:`DRIVING`)
        asks that stop at its first step if none was: leg 2's began as repositioning, braking out of its
        turn, still asked 0.03 m/s; no rest point, the rover rolled back, leapt, the passenger trailed 0.316 m."""
        return (self.min_moving_speed_m_s > 0 and self._stopped_since_s is not None
                and now_s - self._stopped_since_s < RESTART_S)

    def _started(self, u: np.ndarray, yaw: float, moving_m_s: float, dt_s: float, sideways_m_s: float = 0.0,
                 turn: int = 0) -> Tracked:
        """A diff-drive or Ackermann carrier's tracked command for the law's ``u`` [m/s] at heading
        ``yaw`` [rad], its forward speed held to the gentle start and the lead
        (:mod:`mission.carrier.start`) against its measured forward speed ``moving_m_s`` [m/s].

        The caps act on the forward speed asked, after the tracking law has scaled it by the
        heading error, not on the law's planar command before: capped there at the measured
        speed plus the lead, a command then scaled by ``max(cos e, min_speed_fraction)`` asks less
        than the carrier already does, brakes it while it turns, and the next cap is lower still.
        PX4's SIH rover turning onto leg 2 from rest (106 deg) stuck and leapt on that, 0 to
        1-2 m/s every 0.5-2 s for 6 s under a riding passenger (docs/recovery.md, "On real PX4").
        With either cap on, the speed asked also grows at most at ``safety.carrier_max_accel_m_s2``.
        The lead stops the speed asked from running on ahead of a rover that does not follow it; it
        never takes back speed already asked (while the law still asks it). Keyed on the forward
        speed, it did: mid-ride on leg 2 the SIH rover's EKF put 0.9-1.1 m/s of its velocity
        sideways, PX4's speed loop (which reads the velocity's size) slowed the rover, the lead cut
        the speed asked to the forward speed plus 0.3 m/s, down to the floor, PX4 slowed it further,
        to a stop, and it leapt off again: the passenger trailed 0.53 m (docs/recovery.md, "On real PX4").

        Once it moves (forward at :data:`~mission.carrier.start.MOVING_M_S` or ``carrier.floor_from_m_s``,
        whichever is more), or while its velocity's part across its heading, ``sideways_m_s`` [m/s], is
        that large (its estimate cannot tell a crawl from a stand), neither the caps nor the tracking law's
        slowing in a turn ask less than ``carrier.min_moving_speed_m_s`` while the law asks that much (below
        it, the law's own planar speed, which grows at the law's acceleration limit). From a clean stand
        the gentle start stays: asked 0.8 m/s at once on leg 1 the SIH rover leapt to 0.55 m/s in
        0.13 s and the passenger trailed 0.39 m. PX4's rover estimates its speed
        as its velocity's size signed by the forward part, and its EKF's velocity at rest errs
        0.2-0.9 m/s sideways after a drive, so at leg 2's start the caps, keyed on that forward speed,
        asked 0.1-0.8 m/s in turn while its speed loop read +-0.6 m/s, and it swung 0 to 0.9 m/s
        under the riding passenger (docs/recovery.md, "On real PX4")."""
        cmd = track(u, yaw, self.tracking, turn)  # ``turn``: which way round (mission.carrier.guard.P3Guard.away_turn)
        asked = np.array([cmd.speed_m_s])
        capped = float(speed_lead(gentle_start(asked, np.array([self._asked_speed_m_s]), moving_m_s,
                                               self.start_accel_m_s2, dt_s), moving_m_s, self.start_lead_m_s)[0])
        if self.start_lead_m_s > 0:  # the lead holds the speed asked back, it never takes back speed asked
            capped = max(capped, min(self._asked_speed_m_s, cmd.speed_m_s))
        accel = self.model.carrier_safety.max_accel_m_s2
        if (self.start_accel_m_s2 > 0 or self.start_lead_m_s > 0) and accel and dt_s > 0:
            # the law's command runs on while the caps hold the speed asked back: that speed grows
            # at most at the law's acceleration limit from where they left it, as the capped law
            # command did (and its turn onto the bearing does not add to it)
            capped = min(capped, self._asked_speed_m_s + accel * dt_s)
        # the least speed asked while driving: the law's planar speed up to carrier.min_moving_speed_m_s
        # (a vehicle turning in place, asked no forward speed, is left so)
        unsure = max(moving_m_s, sideways_m_s) >= self.floor_from_m_s  # carrier.floor_from_m_s, at least MOVING_M_S
        floor = min(float(np.linalg.norm(u[:2])), self.min_moving_speed_m_s) if cmd.speed_m_s > 0 and unsure else 0.0
        if accel and dt_s > 0:  # a floor that sets in mid-start grows from the speed asked, at the law's ramp
            floor = min(floor, self._asked_speed_m_s + accel * dt_s)
        wanted = max(min(capped, cmd.speed_m_s), floor)
        if wanted != cmd.speed_m_s:  # the same direction: the tracking law's yaw-rate cap goes with the speed
            cmd = track(u * (wanted / cmd.speed_m_s), yaw, self.tracking, turn)
        self._asked_speed_m_s = cmd.speed_m_s
        return cmd

    def course_velocity(self, x_c: np.ndarray, now_s: float, recovery_velocity_m_s: np.ndarray | None = None,
                        yaw_rad: float | None = None) -> np.ndarray | None:
        """RECOVERING: the recovery course's velocity at ``now_s`` [m/s] (dim,) (``recovery_velocity_m_s``
        when given), its clock and its default heading (away from the target) taken at the first
        step of the recovery; REPOSITIONING: straight away from the leg's target at the carrier's
        top speed until its dock point is ``b c + mission.leg_start_margin_m`` (and
        :data:`~mission.config.legs.REPOSITION_SPARE_M`) from it, then zero. A diff-drive or
        Ackermann carrier at heading ``yaw_rad`` [rad] with ``carrier.min_moving_speed_m_s`` > 0 drives
        out :data:`~mission.carrier.legs.TURN_ROOM_M` farther, then towards the target at that speed
        until it heads at it (:meth:`~mission.carrier.legs.Legs.turn_velocity`), so that the leg's
        ride starts straight ahead, then zero (out again, were its turn to end nearer than the start
        distance, or the start to move out: :meth:`~mission.carrier.legs.Legs.wait_out`). Else None.

        The turn is why: PX4's SIH rover stood facing 16-170 deg off the next target's bearing
        when leg 2's ride began, and turned from rest under the riding passenger (docs/recovery.md,
        "On real PX4")."""
        if self.mode is CarrierMode.REPOSITIONING:
            top = float(self.model.carrier_safety.max_speed_m_s or 1.0)
            if self.legs.wait_out(x_c, now_s):  # the passenger still waits: the start moved out, turn afresh
                self._leg_turn = "out"
            if yaw_rad is None or self.tracking.kind == "holonomic" or self.min_moving_speed_m_s <= 0:
                return self.legs.reposition_velocity(x_c, top)
            if self._leg_turn == "out":  # out to the leg's start and the room for the turn
                out = self.legs.reposition_velocity(x_c, top, TURN_ROOM_M)
                if out.any():
                    return out
                self._leg_turn = "turn"
            if self._leg_turn == "turn":
                turn = self.legs.turn_velocity(x_c, yaw_rad, self.min_moving_speed_m_s)
                if turn is not None:
                    return turn
                self._leg_turn = "done"  # it stands from here, whatever its heading wobbles to
            return self.legs.reposition_velocity(x_c, top)
        if self.mode is not CarrierMode.RECOVERING:
            return None
        if recovery_velocity_m_s is not None:
            return pad3(recovery_velocity_m_s)[:self.dim]
        if self._course_start is None:
            self._course_start = (now_s, recovery_heading_deg(self.model, x_c, self.course.speed_m_s))
        t0, away = self._course_start
        return pad3(self.course.velocity_ned_m_s(now_s - t0, away))[:self.dim]


def recovery_heading_deg(model: TickModel, x_c: np.ndarray, speed_m_s: float) -> float:
    """The steady recovery course's default heading [deg] NED from the carrier at ``x_c`` [m]:
    away from ``model``'s target (the served one), turned as little as clears the other targets'
    keep-outs (:func:`mission.carrier.course.clear_heading_deg`, at the steady course's speed
    ``speed_m_s`` [m/s], and clear of the band where it would veer round one,
    :data:`mission.core.tick.ROUND_BAND_M`)."""
    away = away_heading_deg(x_c, np.asarray(model.target))
    others = model.other_keep_outs
    if others is None or not len(others):
        return away
    lim = model.carrier_safety
    return clear_heading_deg(x_c, away, others.centers, others.radii, lim.margin_m, speed_m_s, lim.cbf_gain,
                             ROUND_BAND_M)
