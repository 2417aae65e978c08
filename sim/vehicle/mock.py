"""A PX4-like kinematic MAVLink vehicle for SITL-free testing.

It speaks MAVLink 2 over UDP like a PX4 SITL on its onboard link: HEARTBEAT and the
onboard-profile streams, DO_SET_MODE and COMPONENT_ARM_DISARM with PX4's checks and ACKs,
OFFBOARD with its setpoint rules and failsafes, take-off, land, return and Hold, parameters,
REQUEST_MESSAGE, SET_MESSAGE_INTERVAL and TIMESYNC. MAVSDK connects to it, arms it and flies it.

One thread runs the loop. Each pass it (1) advances the physics in fixed steps of
:data:`PHYSICS_DT_S` simulated seconds up to the clock's time, running the commander's timers at
every step, (2) releases datagrams held by the latency fault, (3) sends the streams that are due,
and (4) waits on the sockets until the next thing is due. Physics and timers run on simulated
time in fixed steps, so a flight at ``speed`` 20 follows the same trajectory as at 1. In lockstep
(``VehicleOptions.lockstep``) the vehicle owns simulated time and steps with the controller
(:mod:`sim.vehicle.lockstep`). ``snapshot()`` reports the true state; all fault times are
simulated seconds. The modules of the package, and where the mock simplifies PX4:
docs/mock-vehicle.md.
"""
from __future__ import annotations

import collections
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any


from mission.time.clock import Clock, ManualClock, ScaledClock
from sim.vehicle import telemetry as tel
from sim.vehicle.modes import Commander
from sim.vehicle.estimator import BiasedEstimateError, EstimateError
from sim.vehicle.faults import FaultInjector, FaultOptions
from sim.vehicle.handlers import MessageHandlers
from sim.vehicle.io import LinkIO
from sim.vehicle.endpoints import VehicleLink, parse_endpoint
from sim.vehicle.options import FRAMES, VehicleOptions, VehicleSnapshot, frozen, status_line
from sim.vehicle.lockstep import LockstepStepper
from sim.vehicle.process import spawn_process
from sim.vehicle.streams import DUE_EPSILON, StreamSchedule
from sim.vehicle.params import ParamTable, vehicle_limits
from sim.vehicle.physics.deck import Deck, DeckMotion
from sim.vehicle.physics.multicopter import KinState, Limits, initial_state, step
from sim.vehicle.physics.rover import rover_stepper

__all__ = ["MockVehicle", "VehicleOptions", "FaultOptions", "VehicleSnapshot", "spawn_process", "PHYSICS_DT_S"]

log = logging.getLogger(__name__)

PHYSICS_DT_S = 0.005  # fixed physics step [s, simulated]
MAX_POLL_WALL_S = 0.02  # longest socket wait [s, wall]; bounds the reaction to stop()
LINK_NAMES = ("onboard", "gcs")
# A PX4 rover is "landed" only when disarmed (RoverLandDetector.cpp): no preflight auto-disarm.
ROVER_PARAMS = {"COM_DISARM_PRFLT": 0.0}

COUNTER_NAMES = (
    "rx_datagrams", "rx_messages", "rx_malformed", "rx_unknown_ids", "rx_unsigned_rejected", "rx_wrong_target",
    "rx_ignored", "commands", "setpoints_accepted", "setpoints_rejected", "params_set", "tx_messages", "tx_errors",
    "dropped_in", "dropped_out", "blackout_in", "blackout_out", "delayed_in", "delayed_out", "physics_steps",
    "internal_errors", "landing_targets_accepted", "landing_targets_ignored",
)


class MockVehicle:
    """The PX4-like vehicle. ``with MockVehicle(opts) as v:`` starts it and stops it on exit.

    ``clock``: the simulated time it flies on (:mod:`mission.time.clock`). By default a
    :class:`~mission.time.clock.ScaledClock` at ``options.speed`` made when it starts; in lockstep a
    :class:`~mission.time.clock.ManualClock` that the vehicle itself advances (it owns time), then a
    scaled clock once the controller is gone. An injected clock is kept (a test's ManualClock
    moves the vehicle's time by hand); in lockstep it must be a ManualClock at 0.
    """

    def __init__(self, options: VehicleOptions | None = None, clock: Clock | None = None) -> None:
        self.options = opts = options or VehicleOptions()
        if opts.lockstep and clock is not None and not (isinstance(clock, ManualClock) and clock.now() == 0.0):
            raise ValueError("a lockstep vehicle owns its time: inject a ManualClock at 0 or none")
        self._own_clock = clock is None
        self.clock: Clock = clock or (ManualClock() if opts.lockstep else ScaledClock(opts.speed))
        self.params = ParamTable({**(ROVER_PARAMS if opts.frame == "rover" else {}), **opts.params}, opts.sysid)
        self._geo = tel.Geo(*opts.home)
        self._kin: KinState = initial_state(opts.start_ned)
        self._commander = Commander(self.params, self._kin)
        self._physics = rover_stepper(lambda: self._commander.mode) if opts.frame == "rover" else step
        self._deck = Deck(opts.deck, lambda: self.params.get("LNDMC_XY_VEL_MAX")) if opts.deck is not None else None
        self._ranges = tel.RangeStream(opts.rangefinder, opts.faults.seed)
        self._commander.refuse_arming_reason = opts.faults.refuse_arming_reason
        self._commander.refuse_offboard_reason = opts.faults.refuse_offboard_reason
        self._faults = FaultInjector(opts.faults)
        self._estimate = estimate_error_of(opts)
        self._noise = tel.PositionNoise(opts.position_noise_m, opts.faults.seed, self._estimate if self._estimate.enabled else None)
        self._schedule = StreamSchedule(LINK_NAMES, self.clock.speed)
        self._links: list[VehicleLink] = []
        self._lock = threading.RLock()
        self._stop_event = threading.Event()
        self._thread: threading.Thread | None = None
        self._steps = 0
        self._limits_cache: tuple[int, Limits] | None = None
        self._counters = dict.fromkeys(COUNTER_NAMES, 0)
        self._position_fault_done = False  # FaultOptions.position_lost_at_s applied
        self._events: collections.deque[tuple[float, int, str]] = collections.deque(maxlen=1000)
        self._unsent: list[tuple[float, int, str]] = []
        self._lockstep = LockstepStepper(self, opts.lockstep_watchdog_wall_s, PHYSICS_DT_S, opts.lockstep_max_speed) if opts.lockstep else None
        self._handlers = MessageHandlers(self)
        self._io = LinkIO(self)

    def __enter__(self) -> MockVehicle:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def start(self) -> None:
        """Bind the sockets and start the loop thread; the clock restarts at 0."""
        if self._thread is not None:
            return
        opts = self.options
        streams: dict = {}  # signing replay state, shared by the links (as PX4's instances share theirs)
        self._links.append(VehicleLink("onboard", parse_endpoint(opts.bind, "udpin"),
                                       parse_endpoint(opts.target, "udpout") if opts.target else None,
                                       opts.sysid, opts.compid, opts.signing_key, streams))
        if opts.gcs_target:
            self._links.append(VehicleLink("gcs", parse_endpoint(opts.gcs_bind, "udpin"), parse_endpoint(opts.gcs_target, "udpout"),
                                           opts.sysid, opts.compid, opts.signing_key, streams))
        if self._own_clock and not opts.lockstep:
            self.clock = ScaledClock(opts.speed)  # time starts now
        self._stop_event.clear()
        self._thread = threading.Thread(target=self._run, name=f"mock-vehicle-{self.port}", daemon=True)
        self._thread.start()
        log.info("mock vehicle sysid %d listening on UDP %d, sending to %s (speed %g)", opts.sysid, self.port,
                 opts.target, opts.speed)

    def stop(self) -> None:
        """Stop the loop and close the sockets (idempotent)."""
        self._stop_event.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        self._thread = None
        for link in self._links:
            link.close()
        self._links.clear()

    @property
    def port(self) -> int:
        """The UDP port the onboard link is bound to (after :meth:`start`)."""
        if not self._links:
            raise RuntimeError("the vehicle is not started")
        return self._links[0].port

    @property
    def gcs_port(self) -> int | None:
        return self._links[1].port if len(self._links) > 1 else None

    # ---- public API (any thread) ---------------------------------------------------------
    @property
    def counters(self) -> dict[str, int]:
        """A copy of the counters (received, malformed, dropped, sent, ...)."""
        with self._lock:
            counters = dict(self._counters)
        counters["held_by_latency"], counters["ranges_sent"] = self._faults.pending(), self._ranges.sent
        return counters

    def snapshot(self) -> VehicleSnapshot:
        """The true state now (advanced to the clock's time first)."""
        with self._lock:
            self._advance_to(self.clock.now())
            k, c = self._kin, self._commander
            return VehicleSnapshot(
                t_s=self._t_s, position_ned_m=frozen((k.n_m, k.e_m, k.d_m)),
                velocity_ned_m_s=frozen((k.vn_m_s, k.ve_m_s, k.vd_m_s)), yaw_rad=k.yaw_rad, armed=c.armed,
                mode=c.mode, landed_state=c.landed_state(c.kin), in_failsafe=c.in_failsafe,
                position_valid=c.position_valid, home_ned_m=frozen(c.home_ned_m),
                last_setpoint_t_s=c.last_setpoint_t_s, counters=self.counters, setpoint=c.setpoint,
                battery_pct=None if (bat := c.battery.reading()) is None else float(bat[0]),
                on_deck=bool(self._deck and self._deck.on_deck), crash=self._deck and self._deck.crash,
                touchdowns=tuple(self._deck.touchdowns) if self._deck else ())

    def when(self, predicate: Callable[[VehicleSnapshot], bool]) -> Callable[[], VehicleSnapshot | None]:
        """A check for :func:`sim.net.wait_for`: the snapshot once ``predicate`` holds for it, else None."""
        def check() -> VehicleSnapshot | None:
            snap = self.snapshot()
            return snap if predicate(snap) else None
        return check

    def event_time(self, text_part: str, after_s: float = -math.inf) -> float | None:
        """Simulated time [s] of the first event after ``after_s`` whose text contains ``text_part``."""
        return next((t for t, _, text in self.events() if t > after_s and text_part in text), None)

    def events(self) -> list[tuple[float, int, str]]:
        """The STATUSTEXTs the vehicle produced: (simulated time [s], severity, text), oldest first.

        The time is the physics step at which the event happened (exact, whatever the speed)."""
        with self._lock:
            return list(self._events)

    def force_mode(self, mode: str) -> None:
        """A pilot takes over and switches to ``mode`` (a name of ``mission.mavlink.px4.MODES``)."""
        with self._lock:
            self._advance_to(self.clock.now())
            self._commander.force_mode(self._t_s, mode)
        log.info("fault: pilot took over in %s", mode)

    def set_faults(self, **changes: Any) -> FaultOptions:
        """Change fault injection at run time (fields of :class:`FaultOptions`)."""
        if "refuse_arming_reason" in changes:
            self.refuse_arming(changes["refuse_arming_reason"])
        if "refuse_offboard_reason" in changes:
            self.refuse_offboard(changes["refuse_offboard_reason"])
        options = self._faults.update(**changes)
        log.info("faults now %s", options)
        return options

    def refuse_arming(self, reason: str | None) -> None:
        """Deny arming with STATUSTEXT ``reason`` (None: allow again)."""
        with self._lock:
            self._commander.refuse_arming_reason = reason

    def refuse_offboard(self, reason: str | None) -> None:
        """Reject DO_SET_MODE OFFBOARD with STATUSTEXT ``reason`` (None: allow again)."""
        with self._lock:
            self._commander.refuse_offboard_reason = reason

    def lose_position_estimate(self, lost: bool = True) -> None:
        """Invalidate (or restore) the position estimate: OFFBOARD is refused and exited."""
        with self._lock:
            self._commander.position_valid = not lost
        log.info("fault: position estimate %s", "lost" if lost else "restored")

    def set_param(self, name: str, value: float) -> None:
        """Set a PX4 parameter as a PARAM_SET would."""
        self.params.set(name, value)

    def status_line(self) -> str:
        """One line for the log: time, mode, position and the counters that reveal trouble."""
        return status_line(self.snapshot())

    def follow_deck(self, source: Callable[[], DeckMotion | None]) -> None:
        """Learn the carrier's motion from ``source`` (its newest, on this vehicle's clock; None:
        nothing new), polled at every pass; needs ``options.deck`` (:mod:`sim.vehicle.physics.deck`)."""
        if self._deck is None:
            raise ValueError("this vehicle has no deck (VehicleOptions.deck)")
        self._deck.source = source

    @property
    def _t_s(self) -> float:
        return self._steps * PHYSICS_DT_S

    def _run(self) -> None:
        if self._lockstep is not None:
            try:
                self._lockstep.run()
            except Exception:  # noqa: BLE001  (log, count, fly on in real time)
                self._counters["internal_errors"] += 1
                log.exception("mock vehicle lockstep error")
            with self._lock:
                self.clock = ScaledClock(self.options.speed, start_s=self._t_s)
        while not self._stop_event.is_set():
            try:
                self._pass()
            except Exception:  # noqa: BLE001  (log, count, keep flying)
                self._counters["internal_errors"] += 1
                log.exception("mock vehicle loop error")
                time.sleep(0.01)

    def _pass(self) -> None:
        now = self.clock.now()
        with self._lock:
            self._advance_to(now)
            self._service_step()
            wait_s = self._wait_wall_s(self._t_s)
        self._io.poll(wait_s)

    def _service_step(self) -> None:
        """At the current step: apply the position fault, release held datagrams, send the
        streams that are due and the commander's STATUSTEXTs (lock held)."""
        lost_at_s = self._faults.options.position_lost_at_s
        if lost_at_s is not None and self._t_s >= lost_at_s and not self._position_fault_done:
            self._position_fault_done = True
            self.lose_position_estimate(True)
        for kind, item in self._faults.due(self._t_s):
            self._io.release(kind, item)
        self._service_streams(self._t_s)
        self._io.send_statustexts()

    def _limits(self) -> Limits:
        """The dynamics' gains and limits from the parameters (derived again only after a change)."""
        cached = self._limits_cache
        if cached is None or cached[0] != self.params.version:
            cached = self._limits_cache = (self.params.version, vehicle_limits(self.params))
        return cached[1]

    def _advance_to(self, t_s: float) -> None:
        """Run the physics and the commander in fixed steps up to simulated time ``t_s``."""
        self._advance_steps(int(t_s / PHYSICS_DT_S))

    def _advance_steps(self, target: int) -> None:
        """Run the physics and the commander up to step number ``target``."""
        if target <= self._steps:
            return
        limits, wind, commander, kin, deck = self._limits(), self.options.wind_ned_m_s, self._commander, self._kin, self._deck
        estimate = self._estimate if self._estimate.enabled else None
        crashed = deck is not None and deck.refresh()
        for k in range(self._steps + 1, target + 1):
            command = commander.step(k * PHYSICS_DT_S, kin if deck is None else deck.as_px4_sees(kin))
            if estimate is not None:  # PX4's controller flies its estimate (sim.vehicle.estimator)
                estimate.advance(PHYSICS_DT_S, commander.taken_off)
                moved = self._physics(kin, command, limits, wind, PHYSICS_DT_S, (estimate.position, estimate.velocity))
            else:
                moved = self._physics(kin, command, limits, wind, PHYSICS_DT_S)
            kin = moved if deck is None else deck.step(k * PHYSICS_DT_S, PHYSICS_DT_S, kin, moved)
            self._ranges.measure(k * PHYSICS_DT_S, kin, deck)
        if deck is not None and deck.crash is not None and not crashed:
            log.warning("crash on the deck at t=%.2f s: %s", deck.touchdowns[-1].t_s, deck.crash)
        self._counters["physics_steps"] += target - self._steps
        self._kin, self._steps = kin, target
        if self._lockstep is not None and isinstance(self.clock, ManualClock):
            self.clock.advance_to(self._t_s)  # the lockstep vehicle owns time
        commander.kin = kin if deck is None else deck.as_px4_sees(kin)
        self._collect_events()

    def _collect_events(self) -> None:
        """Move the commander's STATUSTEXTs to the event log and the send queue."""
        if self._commander.outbox:
            outbox, self._commander.outbox = self._commander.outbox, []
            self._events.extend(outbox)
            self._unsent.extend(outbox)

    def _wait_wall_s(self, t_s: float) -> float:
        """Wall seconds until the physics step at which the next stream or held datagram is due."""
        held = self._faults.next_due_s()
        next_s = min(self._schedule.next_due_s(self._links), math.inf if held is None else held, self._ranges.next_s)
        next_s = t_s + 1.0 if next_s == math.inf else next_s
        wake_s = math.ceil(next_s / PHYSICS_DT_S - DUE_EPSILON) * PHYSICS_DT_S
        return min(max(wake_s - self.clock.now(), 0.0) / self.clock.speed, MAX_POLL_WALL_S)

    def _telemetry_state(self) -> tel.TelemetryState:
        c, k = self._commander, self._kin
        landed = c.landed_state(k if self._deck is None else self._deck.as_px4_sees(k))
        return tel.TelemetryState(self._t_s, k, c.mode, c.armed, c.system_status(), landed, c.armable(),
                                  c.position_valid, c.setpoint, c.home_ned_m, FRAMES[self.options.frame], c.battery.reading())

    def _service_streams(self, t_s: float) -> None:
        state: tel.TelemetryState | None = None
        built: dict[str, Any] = {}  # one message per stream and step, whichever link it goes to
        for link, stream in self._schedule.due(self._links, t_s):
            if stream.name not in built:
                state = state or self._telemetry_state()
                built[stream.name] = tel.build(stream.name, state, self._geo, self._noise)
            if built[stream.name] is not None:
                self._io.send(link, built[stream.name])  # type: ignore[arg-type]  (one of self._links)
        for msg in self._ranges.due(t_s):  # the rangefinder's DISTANCE_SENSOR, latency_s after each capture
            for link in self._links:
                self._io.send(link, msg)


def estimate_error_of(opts: VehicleOptions) -> EstimateError:
    """The errors of the estimate ``opts`` asks for: PX4 SITL's times ``estimate_error`` (a
    quadrotor's), plus the passenger's slow GNSS bias of ``passenger_gnss`` (a quadrotor's, when given)."""
    scale = opts.estimate_error if opts.frame == "quadrotor" else 0.0
    gnss = opts.passenger_gnss
    if gnss is None or gnss.bias_sigma_m <= 0.0 or opts.frame != "quadrotor":
        return EstimateError(scale, seed=opts.faults.seed)
    return BiasedEstimateError(scale, gnss, seed=opts.faults.seed)
