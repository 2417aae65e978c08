"""The carrier-side control loop: own state in, the paper's carrier law, the P3 guard and the
tracking law, a command out to the backend, the carrier's state out on Zenoh.

Every period ``1 / carrier.rate_hz`` [s] of the injected clock the controller

1. lets the backend advance (the built-in kinematic robot integrates its held command; a real
   vehicle moves on its own) and reads the carrier's own state (shared local NED frame);
2. updates its mode from the passenger's newest status (:mod:`mission.carrier.modes`);
3. decides the command: :func:`mission.core.tick.carrier_tick` (paper eq. 4, or while the passenger
   comes home the recovery course of :mod:`mission.carrier.course`; CBF filter, speed and
   acceleration limits), sped up gently while the carrier stands (``carrier.start_accel_m_s2``,
   :mod:`mission.carrier.start`), then :func:`~mission.carrier.tracking.track` (what the robot
   can do), then the P3 guard (:mod:`mission.carrier.guard`), whatever the mode. Steps 2 and 3
   are the carrier's one step, :class:`mission.carrier.step.CarrierStepper` (pure; the recovery
   simulation runs the same); the controller adds what it reads and sends, and its log;
4. sends it to the backend and publishes a :class:`~mission.bus.wire.CarrierState` for the passenger:
   a diff-drive or Ackermann carrier's velocity along its heading (no sideslip,
   :func:`~mission.carrier.tracking.along_heading`), with ``carrier.velocity_bias_tau_s`` made
   consistent with its position (:mod:`mission.core.consistent_velocity`), and with
   ``carrier.acceleration_tau_s`` its measured acceleration (:mod:`mission.carrier.acceleration`).

Failsafes (each a stop: a zero command, still sent, so a PX4 vehicle stays in OFFBOARD and brakes)::

    own state missing or older than carrier.state_timeout_s  -> stop, publish nothing (the
                                                                passenger's carrier_timeout fires)
    passenger lost before separation                         -> PAUSED (stop) until it rides again
    backend not under our control (vehicle lost, pilot took over, not armed/OFFBOARD yet)
                                                             -> stop commanding motion; logged
"""
from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import zenoh

from mission.carrier.acceleration import AccelerationEstimate, inertial_sample
from mission.carrier.backends import CarrierBackend, OwnState
from mission.carrier.frames import HeardBias
from mission.carrier.guard import GuardParams
from mission.carrier.heard import ClosestPair, TeamHeard, hear
from mission.carrier.legs import Legs
from mission.carrier.modes import BEFORE_RIDING, BIND_STATUSES, CarrierMode, PassengerView, lost_reason, on_dock
from mission.carrier.step import (DRIVING, REAL_DELAY_S, STOP, CarrierStepper, carrier_model, guard_params, pad3,
                                  tracking_params)
from mission.carrier.team_bus import TeamBus, views
from mission.carrier.tracking import Tracked, TrackingParams, along_heading
from mission.config.passenger import has_team
from mission.core.consistent_velocity import PositionConsistentVelocity
from mission.bus.auth import BusAuth, bus_auth
from mission.bus.bridge import CarrierPublisher, PassengerFeed
from mission.time.clock import Clock, Periodic
from mission.config.schema import Config
from mission.bus.session import congestion_for
from mission.core.tick import TickModel
from mission.bus.wire import CarrierState

log = logging.getLogger(__name__)

__all__ = ["DRIVING", "REAL_DELAY_S", "STOP", "CarrierController", "CarrierStep", "StepSink", "carrier_model",
           "guard_params", "open_bus", "passenger_view", "tracking_params"]


@dataclass(frozen=True)
class CarrierStep:
    """One step of the carrier controller, for its flight data: t_s [s] clock time; mode;
    hold_reason (None: in control); state the own state used (None: none, or stale); command
    the command sent; law_velocity_m_s [m/s] the filtered law command; guard_active_ticks the
    steps so far on which the P3 guard cut the command; published the state sent to the passenger
    (None: nothing went out); team, a team's carrier only (None for a single pair): every
    passenger as heard at this step and each pair's distance (:mod:`mission.carrier.heard`);
    target_ned_m [m] NED the target of the leg served at this step (None: not known)."""

    t_s: float
    mode: str
    hold_reason: str | None
    state: OwnState | None
    command: Tracked
    law_velocity_m_s: np.ndarray
    guard_active_ticks: int
    published: CarrierState | None
    team: TeamHeard | None = None
    target_ned_m: np.ndarray | None = None


class StepSink(Protocol):
    """Where the carrier's steps go (:class:`mission.flightdata.carrier_log.CarrierLog`): ``step``
    runs in the control loop and must return at once."""

    def step(self, step: CarrierStep) -> None: ...


FRAME_SIGMAS = 3.0  # the frames' disagreement allowed on the dock check with relnav, in standard deviations


def frames_disagree_m(cfg: Config) -> float:
    """How far apart [m] the carrier's and the passenger's frames may be on the dock check: 0 on a
    shared frame; with ``relnav.enabled`` (each vehicle's own GNSS frame) :data:`FRAME_SIGMAS`
    times the standard deviation of the bias's norm (``relnav.bias_sigma_m`` per horizontal axis,
    times ``relnav.vertical_factor`` down), so a passenger riding the carrier's deck in its own
    frame is seen on it, while one claiming RIDING from farther away still is not."""
    r = cfg.relnav
    return FRAME_SIGMAS * r.bias_sigma_m * math.sqrt(2.0 + r.vertical_factor ** 2) if r.enabled else 0.0


def passenger_view(feed: PassengerFeed, dock_ned_m: np.ndarray | None, tolerance_m: float, dim: int) -> PassengerView:
    """The passenger as the carrier sees it now: the newest status of the feed's bound source,
    whether it counts as lost (its token went since the last call, no status, or a stale one),
    whether it is on the dock point ``dock_ned_m`` [m] NED (None: no own state; not on it), and
    the frames' bias it shares (relnav's, :mod:`mission.carrier.frames`), with its receive age."""
    rx = feed.latest()
    lost = lost_reason(feed.alive_over_interval(), None if rx is None else rx.age_s, feed.max_age_s)
    if rx is None:
        return PassengerView(None, False, lost)
    st = rx.status
    near = dock_ned_m is not None and on_dock(st.position_ned_m, dock_ned_m, tolerance_m, dim)
    bias = None if st.bias_ned_m is None or st.bias_sigma_m is None else HeardBias(
        st.bias_ned_m, st.bias_sigma_m, st.stamp_s, rx.age_s)
    return PassengerView(st.phase, st.separated, lost, st.leg, st.reason, st.holding, near, bias)


def open_bus(cfg: Config, session: zenoh.Session, pair: str, clock: Clock,
             encoding: str | None, team: TeamBus | None = None) -> tuple[BusAuth | None, PassengerFeed, CarrierPublisher]:
    """The carrier's end of pair ``pair``'s bus, signed per ``cfg.zenoh`` (:func:`mission.bus.auth.bus_auth`;
    a team's per :attr:`TeamBus.auth`; the auth, else None: unsigned): the passenger's feed, which binds only to a passenger that
    began on the deck (``team``'s first passenger's, a team's), and the carrier's state publisher
    (``encoding`` None: ``zenoh.encoding``)."""
    auth = team.auth if team is not None else bus_auth(cfg.zenoh, pair)
    passenger = team.feeds[0] if team is not None else PassengerFeed(
        session, pair, clock, max_age_s=cfg.carrier.passenger_timeout_s, auth=auth, bind_phases=BEFORE_RIDING,
        bind_samples=BIND_STATUSES)
    try:
        publisher = CarrierPublisher(session, pair, encoding or cfg.zenoh.encoding,  # type: ignore[arg-type]
                                     key=cfg.zenoh.carrier_key, congestion_control=congestion_for(clock), auth=auth)
    except Exception:
        passenger.close()
        raise
    return auth, passenger, publisher


class CarrierController:
    """The carrier of the pair ``cfg.zenoh.pair`` driving ``backend``, on an open Zenoh ``session``.

    ``clock``: the injected clock. ``pair`` and ``encoding`` default to ``cfg.zenoh``. The caller
    owns the session and the backend; :meth:`close` undeclares what the controller declared.
    A ``cfg`` with a ``[team]`` serves every passenger of it (:attr:`team`,
    :mod:`mission.carrier.team_bus`); ``self.cfg`` is then the carrier's own configuration.
    """

    def __init__(self, cfg: Config, clock: Clock, session: zenoh.Session, backend: CarrierBackend, *,
                 pair: str | None = None, encoding: str | None = None, steps: StepSink | None = None) -> None:
        self.pair = pair or cfg.zenoh.pair
        self.team = TeamBus(cfg, session, self.pair, clock, backend.brakes_itself) if has_team(cfg) else None
        if self.team is not None:
            cfg = self.team.own
        self.cfg, self.clock, self.backend, self.steps = cfg, clock, backend, steps
        # the mode machine, the law, the guards (a team's: its TeamCarrier's)
        self.stepper = self.team.carrier.stepper if self.team is not None else CarrierStepper(cfg, backend.brakes_itself)
        self.dim = cfg.scenario.dim
        self.period_s = 1.0 / cfg.carrier.rate_hz
        self.seq = 0
        self.hold_reason: str | None = "no valid own state"
        self._stats: dict[str, Any] = {"closest_target_distance_m": math.inf, "guard_active_ticks": 0,
                                       "stale_ticks": 0, "ticks": 0, "distance_at_separation_m": None,
                                       "braking_distance_m": None, "braking_displacement_m": None,
                                       "stopped_target_distance_m": None,
                                       "closest_each_target_m": [math.inf] * len(self.stepper.legs.targets)}
        self._last_position: np.ndarray | None = None
        self._heard: TeamHeard | None = None  # a team's: its passengers as heard this step
        self._closest_pair = ClosestPair()
        self._after_separation_m = 0.0
        self._separation_position = np.zeros(self.dim)
        self._alignment = np.zeros(3)
        self._aligned = False
        tau = cfg.carrier.acceleration_tau_s
        self._acceleration = AccelerationEstimate(tau) if tau > 0 else None  # published when set
        bias_tau = cfg.carrier.velocity_bias_tau_s
        across = cfg.carrier.velocity_bias_across_tau_s or None
        self._velocity_fix = PositionConsistentVelocity(bias_tau, across) if bias_tau > 0 else None
        try:
            self.auth, self.passenger, self.publisher = open_bus(cfg, session, self.pair, clock, encoding, self.team)
        except Exception:
            if self.team is not None:
                self.team.close()
            raise

    # ------------------------------------------------------------------ decisions
    def dock_point_ned_m(self) -> np.ndarray | None:
        """This carrier's dock point [m] NED (3,): its own position (in the plane, aligned) plus
        mission.dock_offset_ned_m; None without an own state."""
        own = self._in_plane(self.backend.own_state())
        return None if own is None else pad3(own.position_ned_m[:self.dim]) + np.asarray(self.cfg.mission.dock_offset_ned_m)

    # The step's state, read through the controller (its flight data, summary, tests).
    @property
    def mode(self) -> CarrierMode:
        return self.stepper.mode

    @property
    def model(self) -> TickModel:
        """The tick model of the leg the carrier serves."""
        return self.stepper.model

    @property
    def legs(self) -> Legs:
        return self.stepper.legs

    @property
    def guard(self) -> GuardParams:
        return self.stepper.guard

    @property
    def tracking(self) -> TrackingParams:
        return self.stepper.tracking

    @property
    def planar(self) -> bool:
        return self.stepper.planar

    @property
    def velocity_m_s(self) -> np.ndarray:
        """[m/s] the filtered (and, holonomic, guarded) law command."""
        return self.stepper.velocity_m_s

    def _update_mode(self) -> None:
        tolerance = self.cfg.mission.dock_tolerance_m + frames_disagree_m(self.cfg)
        if self.team is not None:
            own = self._in_plane(self.backend.own_state())
            up = self.team.carrier.update_mode(views(self.team, None if own is None else pad3(
                own.position_ned_m[:self.dim]), tolerance, self.dim, passenger_view))
        else:
            view = passenger_view(self.passenger, self.dock_point_ned_m(), tolerance, self.dim)
            up = self.stepper.update_mode(view)
        if up.leg_changed:
            log.info("carrier %s: leg %d, target %s", self.pair, self.legs.index + 1, self.model.target.tolist())
        if up.after is not up.before:
            level = logging.WARNING if up.after in (CarrierMode.PAUSED, CarrierMode.STOPPED) else logging.INFO
            log.log(level, "carrier %s: %s -> %s (%s)", self.pair, up.before.value, up.after.value, up.why)

    def _stopping(self) -> bool:
        return self.stepper.stopping()

    def _decide(self, state: OwnState, dt_s: float, age_s: float) -> Tracked:
        out = self.stepper.decide(state, dt_s, age_s, self.clock.now())
        if not out.feasible:
            log.warning("carrier %s: CBF filter infeasible at %s; holding still", self.pair,
                        state.position_ned_m[:self.dim].tolist())
        if out.guard_active:
            self._stats["guard_active_ticks"] += 1
        if out.frame_change:  # the P3 guard's frame (mission.carrier.frames)
            log_frame_change(self.pair, self.stepper.frame.passenger, out.frame_change)
        return out.tracked

    def _in_plane(self, state: OwnState | None) -> OwnState | None:
        """The own state as the controller uses it: shifted by the deck alignment (if any), and,
        for a planar carrier in 3D, in the plane of scenario.carrier_start (its estimator's height:
        a PX4 rover's EKF altitude drifted 5 m on SITL, is not used or published)."""
        if state is None:
            return None
        p, v = state.position_ned_m + self._alignment, state.velocity_ned_m_s.copy()
        inertial = state.inertial
        if self.planar and self.dim == 3:
            p[2], v[2] = self.cfg.scenario.carrier_start[2], 0.0
            if inertial is not None:
                flat = np.array(inertial.velocity_ned_m_s, dtype=float)
                flat[2] = 0.0
                inertial = OwnState(inertial.t_s, inertial.position_ned_m, flat, inertial.yaw_rad)
        return OwnState(state.t_s, p, v, state.yaw_rad, inertial)

    def _align_on_deck(self) -> None:
        """carrier.align_on_deck_m > 0: while the passenger still stands on the deck (PREFLIGHT ..
        ARMING, fresh), shift the own horizontal position onto the passenger's, once, if the
        two estimates differ by at most that much (two GPS-based EKFs disagree by ~1 m). Until
        then the carrier publishes nothing: the passenger waits for it.

        Trust: a passenger that lies about where it stands moves the carrier's frame by at most
        align_on_deck_m; the P3 guard holds in the aligned (the passenger's) frame."""
        limit = self.cfg.carrier.align_on_deck_m
        if limit <= 0 or self._aligned or self.mode is not CarrierMode.WAITING:
            return
        rx = self.passenger.latest()
        if rx is None or rx.stale or not rx.status.phase.on_deck:
            return
        own = self.backend.own_state()
        if own is None:
            return
        shift = np.zeros(3)
        shift[:2] = rx.status.position_ned_m[:2] - own.position_ned_m[:2]
        self._aligned = True
        if float(np.linalg.norm(shift)) > limit:
            log.warning("carrier %s: passenger on the deck is %.2f m away (> carrier.align_on_deck_m = %g): not aligning",
                        self.pair, float(np.linalg.norm(shift)), limit)
            return
        self._alignment = shift
        log.info("carrier %s: aligned on the passenger standing on the deck: shift %s m", self.pair,
                 np.round(shift, 3).tolist())

    def _account(self, state: OwnState) -> None:
        """Closest approach |e_tc|, distance when the separation was heard, path length and
        straight-line displacement after it (the braking distance), distance where it stopped."""
        x = state.position_ned_m[:self.dim]
        dist = float(np.linalg.norm(np.asarray(self.model.target) - x))
        s = self._stats
        s["closest_target_distance_m"] = min(s["closest_target_distance_m"], self.legs.closest_m(x))  # to any target
        s["closest_each_target_m"] = [min(d, float(np.linalg.norm(np.asarray(t)[:self.dim] - x)))
                                      for d, t in zip(s["closest_each_target_m"], self.legs.targets)]
        if self.mode is CarrierMode.SEPARATED:
            if s["distance_at_separation_m"] is None:
                s["distance_at_separation_m"] = dist
                self._separation_position = x.copy()
            elif self._last_position is not None:
                self._after_separation_m += float(np.linalg.norm(x - self._last_position))
            s["braking_distance_m"] = self._after_separation_m  # path length
            s["braking_displacement_m"] = float(np.linalg.norm(x - self._separation_position))
            s["stopped_target_distance_m"] = dist
        self._last_position = x.copy()
        self.stepper.frame.account(x, self.legs.targets)  # the same in the guard's frame

    # ------------------------------------------------------------------ stepping
    def step(self, dt_s: float) -> CarrierState | None:
        """Advance ``dt_s`` [s], decide and send the next command, publish and return the state
        published (None when the own state is stale: a stop, nothing published)."""
        if dt_s < 0:
            raise ValueError(f"dt_s must be >= 0, got {dt_s!r}")
        self.backend.advance(dt_s)
        self._stats["ticks"] += 1
        self._update_mode()
        self._align_on_deck()
        if self.mode in (CarrierMode.APPROACHING, CarrierMode.RECOVERING):
            self.backend.engage()
        elif self.mode in (CarrierMode.SEPARATED, CarrierMode.STOPPED, CarrierMode.PARKED) and self._stopping() and not (
                self.mode is CarrierMode.SEPARATED and self.cfg.mission.final_action == "return"):
            self.backend.park()  # stopped for good (with a recovery to come it keeps control): PX4 holds in Hold
        state = self._in_plane(self.backend.own_state())
        now = self.clock.now()
        self._hear_team(now)
        why: str | None
        if state is None:
            why = "no valid own state"
        elif now - state.t_s > self.cfg.carrier.state_timeout_s:
            why = f"own state {now - state.t_s:.2f} s old (> {self.cfg.carrier.state_timeout_s} s)"
        elif state.yaw_rad is None and self.tracking.kind != "holonomic":
            why = "no heading yet (a robot that moves along its heading cannot be steered or guarded without it)"
        else:
            why = self.backend.control_fault()
        if why != self.hold_reason:
            if why is None:
                log.info("carrier %s: in control (%s backend)", self.pair, self.backend.name)
            else:
                log.warning("carrier %s: stopped: %s", self.pair, why)
            self.hold_reason = why
        if state is None or now - state.t_s > self.cfg.carrier.state_timeout_s:
            if self._acceleration is not None:
                self._acceleration.reset()
            if self._velocity_fix is not None:
                self._velocity_fix.reset()
            self._stats["stale_ticks"] += 1
            self.stepper.hold()
            self.backend.command(STOP)
            trace(self, now, None, STOP, None)
            return None
        cmd = self._decide(state, dt_s, now - state.t_s) if why is None else STOP
        if why is not None:
            self.stepper.hold()
        self.backend.command(cmd)
        self._account(state)
        fresh = self._in_plane(self.backend.own_state()) or state  # the built-in robot now holds the new command
        velocity = pad3(fresh.velocity_ned_m_s[:self.dim])
        if self.tracking.kind != "holonomic" and fresh.yaw_rad is not None:
            velocity = along_heading(velocity, fresh.yaw_rad)  # no sideslip: the estimator's wander removed
        if self._velocity_fix is not None:  # consistent with its position (mission.core.consistent_velocity)
            velocity = self._velocity_fix.update(fresh.t_s, pad3(fresh.position_ned_m[:self.dim]), velocity, fresh.yaw_rad)
        accel = None if self._acceleration is None else self._acceleration.update(
            *inertial_sample(fresh, velocity, self.dim, self.tracking.kind != "holonomic"))
        out = CarrierState(fresh.t_s, self.seq, "local_ned", pad3(fresh.position_ned_m[:self.dim]), velocity,
                           fresh.yaw_rad, accel, None if self.team is None else self.team.target_ned_m())
        if self.cfg.carrier.align_on_deck_m > 0 and not self._aligned:
            trace(self, now, state, cmd, None)
            return out  # not yet placed in the passenger's frame: nothing the passenger should use
        self.publisher.publish(out)
        self.seq += 1
        trace(self, now, state, cmd, out)
        return out

    def _hear_team(self, now: float) -> None:
        """A team's: this step's snapshot of every passenger as heard, each pair's distance, and
        the closest pair so far (:mod:`mission.carrier.heard`)."""
        if self.team is None:
            return
        self._heard = hear(self.team.heard(), self.team.max_age_s)
        self._closest_pair.update(now, self._heard)

    def run(self, stop_event: threading.Event, duration_s: float | None = None) -> None:
        """Step at ``carrier.rate_hz`` on the clock until ``stop_event`` is set or ``duration_s``
        [s] of clock time has passed. Steps once at the clock's first instant (at once on a
        scaled clock, at the first barrier in lockstep)."""
        self.clock.sleep(0.0)
        t0 = last = self.clock.now()
        periodic = Periodic(self.clock, self.period_s)
        self.step(0.0)
        log.info("carrier %s (%s backend) publishing on %s at %.1f Hz (clock speed %g)", self.pair,
                 self.backend.name, self.publisher.key, self.cfg.carrier.rate_hz, self.clock.speed)
        while not stop_event.is_set():
            tick = periodic.wait()
            if duration_s is not None and tick - t0 >= duration_s:
                break
            self.step(tick - last)
            last = tick
        if periodic.overruns:
            log.warning("carrier %s: %d overruns of the %.1f ms period", self.pair, periodic.overruns, 1e3 * self.period_s)

    def summary(self) -> dict[str, Any]:
        """Closest approach to the target, distance when the separation was heard, braking
        distance after it [m], guard and stale tick counts, mode; a team's carrier adds its
        feeds' counters and ``closest_pair``, the closest two passengers as heard
        (:meth:`mission.carrier.heard.ClosestPair.summary`)."""
        out = dict(self._stats)
        out.update(mode=self.mode.value, guard_radius_m=self.guard.radius_m, backend=self.backend.name,
                   deck_alignment_m=self._alignment.tolist(), p3_frame=self.stepper.frame.summary(),
                   separation_distance_m=self.model.law.separation_distance_m,
                   passenger_feed=self.passenger.counters, **({} if self.team is None else self.team.counters()))
        if self.team is not None:
            out["closest_pair"] = self._closest_pair.summary()
        if math.isinf(out["closest_target_distance_m"]):
            out["closest_target_distance_m"] = None
        out["closest_each_target_m"] = [None if math.isinf(d) else d for d in out["closest_each_target_m"]]
        return out

    def close(self) -> None:
        """Undeclare the publisher, the liveliness token and the passenger subscribers."""
        self.publisher.close()
        self.passenger.close()
        if self.team is not None:
            self.team.close()

    def __enter__(self) -> "CarrierController":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def log_frame_change(pair: str, passenger: bool, change: str) -> None:
    """Log what changed in the P3 guard's frame: into the passenger's (info), or a fall back to the
    carrier's own with the margin widened (warning)."""
    log.log(logging.INFO if passenger else logging.WARNING, "carrier %s: %s", pair, change)


def trace(ctl: CarrierController, t_s: float, state: OwnState | None, cmd: Tracked,
          published: CarrierState | None) -> None:
    """Hand the step just taken to the controller's :class:`StepSink`, if it has one."""
    if ctl.steps is not None:
        ctl.steps.step(CarrierStep(t_s, ctl.mode.value, ctl.hold_reason, state, cmd, ctl.velocity_m_s,
                                   ctl._stats["guard_active_ticks"], published, ctl._heard, ctl.model.target))
