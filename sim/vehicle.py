"""A PX4-like kinematic MAVLink vehicle for SITL-free testing (issue 3).

It speaks MAVLink 2 over UDP like a PX4 SITL on its onboard link (../shared/REFERENCE.md is the
specification): HEARTBEAT and the onboard-profile streams from start-up, DO_SET_MODE and
COMPONENT_ARM_DISARM with PX4's checks and ACKs, OFFBOARD with its setpoint rules and failsafes,
NAV_TAKEOFF / NAV_LAND / NAV_RETURN_TO_LAUNCH / Hold, the parameter protocol, REQUEST_MESSAGE,
SET_MESSAGE_INTERVAL and TIMESYNC. MAVSDK connects to it, arms it and flies it offboard.

Structure: one thread runs the loop. Each pass it (1) advances the physics in fixed steps of
:data:`PHYSICS_DT_S` simulated seconds up to the clock's time, running the commander's timers at
every step, (2) releases datagrams held by the latency fault, (3) sends the streams that are due,
and (4) waits on the sockets until the next thing is due. Because physics and timers run on
simulated time in fixed steps, a flight at ``speed`` 20 follows the same trajectory as at 1.

Modules: :mod:`sim.vehicle_physics` (PX4's position controller on an SIH-like airframe), :mod:`sim.vehicle_commander` (modes, arming,
failsafes), :mod:`sim.vehicle_telemetry` (streams, messages, geodesy), :mod:`sim.vehicle_params`
(parameter table), :mod:`sim.vehicle_protocol` (what PX4 makes of a command or setpoint),
:mod:`sim.vehicle_faults` (loss, latency, blackouts), :mod:`sim.vehicle_link` (UDP endpoints,
codec, signing), :mod:`sim.vehicle_probe` (a pymavlink peer for tests and the bench).

Choices where PX4 leaves room, or where the mock simplifies (see also the commander's docstring):
- Setpoints are read as PX4 reads them (:func:`sim.vehicle_protocol.setpoint_of`): any
  combination of position, velocity and acceleration in LOCAL_NED, velocity and acceleration in
  BODY_NED, flown by PX4's position controller (:mod:`sim.mc_position_control`). Another frame, the
  FORCE bit with an acceleration, or nothing to control: dropped with PX4's STATUSTEXT (*at most
  once a second per text), counted in ``setpoints_rejected``, and not proof of life.
- Latency is one-way and applies in each direction; loss and blackouts too. All fault times are
  simulated seconds.
- STATUSTEXT goes only to a link whose peer sent a HEARTBEAT within 2.5 s (as PX4 does);
  ``VehicleOptions.statustext_needs_heartbeat=False`` sends them regardless.
- Ground: ``d = 0`` of the local frame (the origin's altitude, ``home``). A start with ``d < 0``
  stands on a platform at that height (a passenger on its carrier's deck) until it lifts off.
- Home is set where the vehicle arms on the ground; ``home`` (lat, lon, alt) is the EKF origin.
- ``snapshot()`` reports the true state; ``position_noise_m`` only affects the telemetry.
- Streams: PX4's onboard profile at its rates (:mod:`sim.vehicle_telemetry`), kept per link and
  changed by SET_MESSAGE_INTERVAL on the link it arrives on, as PX4 does. Stream rates scale with
  ``speed`` up to wall-clock caps (LOCAL_POSITION_NED and HEARTBEAT 300 Hz, ATTITUDE
  100 Hz, the others 50 Hz). The vehicle's own TIMESYNC requests are not streamed.
- Offboard loss with COM_OBL_RC_ACT = 0 and no RC: POSCTL that holds position and descends, as
  seen on a 2025 SITL; not PX4 2026's fall-through to NAV_RCL_ACT (PR #26289).
"""
from __future__ import annotations

import collections
import logging
import math
import os
import select
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mission import px4
from mission.clock import ScaledClock
from mission.mavlink_env import mavlink
from sim import vehicle_telemetry as tel
from sim.vehicle_commander import Commander
from sim.vehicle_estimator import EstimateDrift, flown_on_estimate
from sim.vehicle_faults import FaultInjector, FaultOptions
from sim.vehicle_link import VehicleLink, parse_endpoint
from sim.vehicle_params import ParamTable, UnknownParam, vehicle_limits
from sim.vehicle_physics import KinState, Limits, initial_state, step
from sim.vehicle_protocol import int_param, mode_of_set_mode, param_value, setpoint_of
from sim.rover_physics import rover_stepper

__all__ = ["MockVehicle", "VehicleOptions", "FaultOptions", "VehicleSnapshot", "spawn_process", "PHYSICS_DT_S"]

log = logging.getLogger(__name__)

PHYSICS_DT_S = 0.005  # fixed physics step [s, simulated]
MAX_POLL_WALL_S = 0.02  # longest socket wait [s, wall]; bounds the reaction to stop()
DUE_EPSILON = 1e-9  # [s] tolerance when comparing due times with the step grid
RX_BATCH = 256  # datagrams read per socket per pass
STATUSTEXT_PEER_TIMEOUT_S = 2.5  # PX4 treats a peer without HEARTBEAT for this long as gone
LOCKSTEP_HELLO_WALL_S = 0.05  # lockstep: resend period of the first barrier until a controller answers [s, wall]
LINK_NAMES = ("onboard", "gcs")
FRAMES = {"quadrotor": px4.MAV_TYPE_QUADROTOR, "rover": px4.MAV_TYPE_GROUND_ROVER}
# A PX4 rover is "landed" only when disarmed (RoverLandDetector.cpp): no preflight auto-disarm.
ROVER_PARAMS = {"COM_DISARM_PRFLT": 0.0}

COUNTER_NAMES = (
    "rx_datagrams", "rx_messages", "rx_malformed", "rx_unknown_ids", "rx_unsigned_rejected", "rx_wrong_target",
    "rx_ignored", "commands", "setpoints_accepted", "setpoints_rejected", "params_set", "tx_messages", "tx_errors",
    "dropped_in", "dropped_out", "blackout_in", "blackout_out", "delayed_in", "delayed_out", "physics_steps",
    "internal_errors",
)


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
    (seeded by ``faults.seed``). estimate_drift_m_s: the reported position wanders as PX4's
    estimate does (std of the drift rate [m/s]; PX4 SITL: 0.18, :mod:`sim.vehicle_estimator`);
    0 (default): no wander.
    signing_key: 32-byte MAVLink 2 signing key; then unsigned messages other than HEARTBEAT
    are rejected and everything sent is signed.
    lockstep: own simulated time and step in lockstep with the controller on the onboard link
    (:mod:`mission.lockstep`); ``speed`` is then the pace after the controller leaves or stays
    silent for ``lockstep_watchdog_wall_s`` wall seconds.
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
    estimate_drift_m_s: float = 0.0
    statustext_needs_heartbeat: bool = True
    frame: str = "quadrotor"  # or "rover": MAV_TYPE_GROUND_ROVER, Ackermann kinematics (sim.rover_physics)
    lockstep: bool = False
    lockstep_watchdog_wall_s: float = 10.0  # mission.lockstep.VEHICLE_WATCHDOG_WALL_S

    def __post_init__(self) -> None:
        if not self.speed > 0:
            raise ValueError(f"speed must be > 0, got {self.speed!r}")
        if not 1 <= self.sysid <= 255 or not 1 <= self.compid <= 255:
            raise ValueError(f"sysid and compid must be in 1..255, got {self.sysid}, {self.compid}")
        if self.signing_key is not None and len(self.signing_key) != 32:
            raise ValueError(f"signing_key must be 32 bytes, got {len(self.signing_key)}")
        if not self.estimate_drift_m_s >= 0:
            raise ValueError(f"estimate_drift_m_s must be >= 0, got {self.estimate_drift_m_s!r}")
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


def _frozen(values: Sequence[float]) -> np.ndarray:
    array = np.array(values, dtype=float)
    array.flags.writeable = False
    return array


class MockVehicle:
    """The PX4-like vehicle. ``with MockVehicle(opts) as v:`` starts it and stops it on exit."""

    def __init__(self, options: VehicleOptions | None = None) -> None:
        self.options = opts = options or VehicleOptions()
        self.clock: ScaledClock | _StepClock = _StepClock(self) if opts.lockstep else ScaledClock(opts.speed)
        self.params = ParamTable({**(ROVER_PARAMS if opts.frame == "rover" else {}), **opts.params}, opts.sysid)
        self._geo = tel.Geo(*opts.home)
        self._kin: KinState = initial_state(opts.start_ned)
        self._commander = Commander(self.params, self._kin)
        self._physics = rover_stepper(lambda: self._commander.mode) if opts.frame == "rover" else step
        self._commander.refuse_arming_reason = opts.faults.refuse_arming_reason
        self._commander.refuse_offboard_reason = opts.faults.refuse_offboard_reason
        self._faults = FaultInjector(opts.faults)
        self._drift = EstimateDrift(opts.estimate_drift_m_s, seed=opts.faults.seed)
        self._noise = tel.PositionNoise(opts.position_noise_m, opts.faults.seed, self._drift if self._drift.enabled else None)
        # per link, as PX4 keeps them: SET_MESSAGE_INTERVAL changes the link it arrived on
        self._streams = {name: tel.make_streams(1.0 if opts.lockstep else opts.speed) for name in LINK_NAMES}
        self._links: list[VehicleLink] = []
        self._lock = threading.RLock()
        self._stop_event = threading.Event()
        self._thread: threading.Thread | None = None
        self._steps = 0
        self._limits_cache: tuple[int, Limits] | None = None
        self._counters = dict.fromkeys(COUNTER_NAMES, 0)
        self._chunk_id = 0
        self._position_fault_done = False  # FaultOptions.position_lost_at_s applied
        self._events: collections.deque[tuple[float, int, str]] = collections.deque(maxlen=1000)
        self._unsent: list[tuple[float, int, str]] = []
        self._barrier_ns = -1  # lockstep: the step the vehicle waits at
        self._lockstep_answer: int | None = None  # the controller's answer (its next wake [ns])
        self._marked_steps = -1  # lockstep: last step announced by SYSTEM_TIME
        self._batching = False  # lockstep: a step's packets go out as one datagram per link
        self._command_handlers: dict[int, Callable[[VehicleLink, list[float]], tuple[int, list[Any]]]] = {
            px4.MAV_CMD_DO_SET_MODE: self._cmd_set_mode,
            px4.MAV_CMD_COMPONENT_ARM_DISARM: self._cmd_arm_disarm,
            px4.MAV_CMD_NAV_TAKEOFF: self._cmd_takeoff,
            px4.MAV_CMD_NAV_LAND: lambda link, p: (self._commander.set_mode(self._t_s, "AUTO.LAND"), []),
            px4.MAV_CMD_NAV_RETURN_TO_LAUNCH: lambda link, p: (self._commander.set_mode(self._t_s, "AUTO.RTL"), []),
            px4.MAV_CMD_REQUEST_MESSAGE: self._cmd_request_message,
            px4.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: lambda link, p: (px4.MAV_RESULT_ACCEPTED, [tel.autopilot_version(opts.sysid)]),
            px4.MAV_CMD_SET_MESSAGE_INTERVAL: self._cmd_set_message_interval,
            px4.MAV_CMD_GET_MESSAGE_INTERVAL: self._cmd_get_message_interval,
        }
        self._handlers: dict[str, Callable[[VehicleLink, Any], None]] = {
            "HEARTBEAT": self._on_heartbeat,
            "COMMAND_LONG": self._on_command_long,
            "COMMAND_INT": self._on_command_int,
            "SET_POSITION_TARGET_LOCAL_NED": self._on_setpoint,
            "PARAM_REQUEST_LIST": self._on_param_request_list,
            "PARAM_REQUEST_READ": self._on_param_request_read,
            "PARAM_SET": self._on_param_set,
            "TIMESYNC": self._on_timesync,
        }

    # ---- lifetime ------------------------------------------------------------------------
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
        self._links.append(VehicleLink("onboard", parse_endpoint(opts.bind, "udpin"),
                                       parse_endpoint(opts.target, "udpout") if opts.target else None,
                                       opts.sysid, opts.compid, opts.signing_key))
        if opts.gcs_target:
            self._links.append(VehicleLink("gcs", parse_endpoint(opts.gcs_bind, "udpin"), parse_endpoint(opts.gcs_target, "udpout"),
                                           opts.sysid, opts.compid, opts.signing_key))
        self.clock = _StepClock(self) if opts.lockstep else ScaledClock(opts.speed)
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
        counters["held_by_latency"] = self._faults.pending()
        return counters

    def snapshot(self) -> VehicleSnapshot:
        """The true state now (advanced to the clock's time first)."""
        with self._lock:
            self._advance_to(self.clock.now())
            k, c = self._kin, self._commander
            return VehicleSnapshot(
                t_s=self._t_s, position_ned_m=_frozen((k.n_m, k.e_m, k.d_m)),
                velocity_ned_m_s=_frozen((k.vn_m_s, k.ve_m_s, k.vd_m_s)), yaw_rad=k.yaw_rad, armed=c.armed,
                mode=c.mode, landed_state=c.landed_state(k), in_failsafe=c.in_failsafe,
                position_valid=c.position_valid, home_ned_m=_frozen(c.home_ned_m),
                last_setpoint_t_s=c.last_setpoint_t_s, counters=self.counters)

    def wait_for(self, predicate: Callable[[VehicleSnapshot], bool], timeout_s: float = 5.0,
                 poll_s: float = 0.002) -> VehicleSnapshot | None:
        """Poll :meth:`snapshot` until ``predicate`` holds; None after ``timeout_s`` wall seconds."""
        deadline = time.monotonic() + timeout_s
        while True:
            snap = self.snapshot()
            if predicate(snap):
                return snap
            if time.monotonic() >= deadline:
                return None
            time.sleep(poll_s)

    def event_time(self, text_part: str, after_s: float = -math.inf) -> float | None:
        """Simulated time [s] of the first event after ``after_s`` whose text contains ``text_part``."""
        return next((t for t, _, text in self.events() if t > after_s and text_part in text), None)

    def events(self) -> list[tuple[float, int, str]]:
        """The STATUSTEXTs the vehicle produced: (simulated time [s], severity, text), oldest first.

        The time is the physics step at which the event happened (exact, whatever the speed)."""
        with self._lock:
            return list(self._events)

    def force_mode(self, mode: str) -> None:
        """A pilot takes over and switches to ``mode`` (a name of ``mission.px4.MODES``)."""
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
        s = self.snapshot()
        c = s.counters
        n, e, d = s.position_ned_m
        return (f"t={s.t_s:.1f}s {s.mode} {'ARMED' if s.armed else 'disarmed'}{' FAILSAFE' if s.in_failsafe else ''} "
                f"ned=({n:.1f},{e:.1f},{d:.1f}) rx={c['rx_messages']} malformed={c['rx_malformed']} "
                f"unknown_ids={c['rx_unknown_ids']} unsigned={c['rx_unsigned_rejected']} wrong_target={c['rx_wrong_target']} "
                f"sp={c['setpoints_accepted']}/{c['setpoints_rejected']}rej tx={c['tx_messages']} "
                f"drop_in={c['dropped_in'] + c['blackout_in']} drop_out={c['dropped_out'] + c['blackout_out']}")

    # ---- the loop ------------------------------------------------------------------------
    @property
    def _t_s(self) -> float:
        return self._steps * PHYSICS_DT_S

    def _run(self) -> None:
        if self.options.lockstep:
            try:
                self._run_lockstep()
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
        self._poll(wait_s)

    def _service_step(self) -> None:
        """At the current step: apply the position fault, release held datagrams, send the
        streams that are due and the commander's STATUSTEXTs (lock held)."""
        lost_at_s = self._faults.options.position_lost_at_s
        if lost_at_s is not None and self._t_s >= lost_at_s and not self._position_fault_done:
            self._position_fault_done = True
            self.lose_position_estimate(True)
        for kind, item in self._faults.due(self._t_s):
            self._release(kind, item)
        self._service_streams(self._t_s)
        self._flush_outbox()

    # ---- lockstep (mission.lockstep documents the protocol) --------------------------------
    def _run_lockstep(self) -> None:
        """Own simulated time: at each barrier send TIMESYNC(0, t) and wait for the controller's
        answer (tc1 = its next wake) before integrating up to that wake, step by step, with the
        streams, faults and commands of every step. Returns when the controller leaves or is
        silent for ``lockstep_watchdog_wall_s`` (the caller goes on in real time) or on stop().
        Each step's packets go out as one datagram per link (SYSTEM_TIME first, the barrier last)."""
        self._batching = True
        try:
            self._step_until_left()
        finally:
            with self._lock:
                self._flush_links()
                self._batching = False

    def _step_until_left(self) -> None:
        onboard, joined = self._links[0], False
        watchdog_s = self.options.lockstep_watchdog_wall_s
        while not self._stop_event.is_set():
            with self._lock:
                self._service_step()
                self._barrier_ns, self._lockstep_answer = self._t_ns, None
                self._send_control(onboard, mavlink.MAVLink_timesync_message(0, self._t_ns))
                self._flush_links()
            called = time.monotonic()
            answer = None
            while not self._stop_event.is_set():
                self._poll(MAX_POLL_WALL_S)
                answer = self._lockstep_answer
                if answer is not None:
                    break
                now = time.monotonic()
                if not joined and now - called > LOCKSTEP_HELLO_WALL_S:  # nobody answered yet: hello again
                    with self._lock:  # (time has not started: no link faults yet, or latency would hold it forever)
                        heartbeat = tel.build("HEARTBEAT", self._telemetry_state(), self._geo, self._noise)
                        self._send_control(onboard, heartbeat)
                        self._send_control(onboard, mavlink.MAVLink_timesync_message(0, self._t_ns))
                        self._flush_links()
                    called = now
                elif joined and now - called > watchdog_s:
                    log.warning("lockstep: no answer for step t = %.3f s within %.1f s (wall); the controller is "
                                "gone, going on in real time at speed %g", self._t_s, watchdog_s, self.options.speed)
                    return
            if answer is None:
                return
            if answer < 0:
                log.info("lockstep: the controller left at t = %.3f s; going on in real time at speed %g",
                         self._t_s, self.options.speed)
                return
            joined = True
            target = max(self._steps + 1, math.ceil(answer / self._step_ns - 1e-6))
            with self._lock:
                while self._steps < target - 1:
                    self._advance_steps(self._steps + 1)
                    self._service_step()
                    self._flush_links()
                self._advance_steps(target)

    @property
    def _step_ns(self) -> int:
        return round(PHYSICS_DT_S * 1e9)

    @property
    def _t_ns(self) -> int:
        return self._steps * self._step_ns

    def _send_control(self, link: VehicleLink, msg: Any) -> None:
        """Send a lockstep clock message: never through the link faults, never counted."""
        if link.target is not None and self._batching:
            link.queue(link.pack(msg), counted=False)
        elif link.target is not None:
            link.sendto(link.pack(msg), link.target)

    def _mark_time(self, link: VehicleLink) -> None:
        """In lockstep, precede the first datagram of a step on the onboard link with
        SYSTEM_TIME, so the controller stamps what follows with this step's time."""
        if self.options.lockstep and link is self._links[0] and self._marked_steps != self._steps:
            self._marked_steps = self._steps
            self._send_control(link, mavlink.MAVLink_system_time_message(0, self._t_ns // 1_000_000))

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
        limits, wind, commander, kin = self._limits(), self.options.wind_ned_m_s, self._commander, self._kin
        drift = self._drift if self._drift.enabled else None
        for k in range(self._steps + 1, target + 1):
            command = commander.step(k * PHYSICS_DT_S, kin)
            if drift is not None:  # PX4 flies its (wandering) estimate to a position setpoint
                drift.advance(PHYSICS_DT_S)
                command = flown_on_estimate(command, drift.offset)
            kin = self._physics(kin, command, limits, wind, PHYSICS_DT_S)
        self._counters["physics_steps"] += target - self._steps
        self._kin, self._steps = kin, target
        commander.kin = kin
        self._collect_events()

    def _collect_events(self) -> None:
        """Move the commander's STATUSTEXTs to the event log and the send queue."""
        if self._commander.outbox:
            outbox, self._commander.outbox = self._commander.outbox, []
            self._events.extend(outbox)
            self._unsent.extend(outbox)

    def _wait_wall_s(self, t_s: float) -> float:
        """Wall seconds until the physics step at which the next stream or held datagram is due."""
        due = [s.next_due_s for link in self._links for s in self._streams[link.name].values() if s.period_s > 0]
        held = self._faults.next_due_s()
        if held is not None:
            due.append(held)
        next_s = min(due, default=t_s + 1.0)
        wake_s = math.ceil(next_s / PHYSICS_DT_S - DUE_EPSILON) * PHYSICS_DT_S
        return min(max(wake_s - self.clock.now(), 0.0) / self.clock.speed, MAX_POLL_WALL_S)

    def _poll(self, wait_s: float) -> None:
        links = list(self._links)
        try:
            ready, _, _ = select.select([link.sock for link in links], [], [], wait_s)
        except (OSError, ValueError):  # closed by stop()
            return
        for link in links:
            if link.sock in ready:
                self._drain(link)

    def _drain(self, link: VehicleLink) -> None:
        for _ in range(RX_BATCH):
            try:
                data, address = link.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return
            with self._lock:
                self._advance_to(self.clock.now())
                if self.options.lockstep and _is_timesync(data):
                    self._clock_message(link, data, address)
                else:
                    self._admit_in(link, data, address)
                self._flush_links()

    def _clock_message(self, link: VehicleLink, data: bytes, address: tuple[str, int]) -> None:
        """A lockstep TIMESYNC: the simulation's own clock, so no link faults and no counters."""
        messages, _ = link.parse(data)
        for msg in messages:
            if msg.get_type() == "TIMESYNC":
                link.latch(address)
                self._on_timesync(link, msg)

    def _admit_in(self, link: VehicleLink, data: bytes, address: tuple[str, int]) -> None:
        fate, delay_s = self._faults.admit("in", self._t_s)
        if fate == "blackout":
            self._counters["blackout_in"] += 1
        elif fate == "lost":
            self._counters["dropped_in"] += 1
        elif fate == "delay":
            self._counters["delayed_in"] += 1
            self._faults.hold(self._t_s + delay_s, "in", (link, data, address))
        else:
            self._process(link, data, address)

    def _release(self, kind: str, item: Any) -> None:
        if kind == "in":
            self._process(*item)
        else:
            link, data = item
            if link.target is not None and link in self._links:
                self._emit(link, data)

    # ---- receiving -----------------------------------------------------------------------
    def _process(self, link: VehicleLink, data: bytes, address: tuple[str, int]) -> None:
        self._counters["rx_datagrams"] += 1
        messages, leftover = link.parse(data)
        if leftover:
            self._counters["rx_malformed"] += 1
        for msg in messages:
            self._dispatch(link, msg, address)
        self._flush_outbox()

    def _dispatch(self, link: VehicleLink, msg: Any, address: tuple[str, int]) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            unsigned = "signature" in str(getattr(msg, "reason", ""))
            self._counters["rx_unsigned_rejected" if unsigned else "rx_malformed"] += 1
            log.debug("rx %s from %s: %s", kind, address, getattr(msg, "reason", ""))
            return
        if kind.startswith("UNKNOWN_"):
            self._counters["rx_unknown_ids"] += 1
            return
        self._counters["rx_messages"] += 1
        link.latch(address)
        handler = self._handlers.get(kind)
        if handler is None:
            self._counters["rx_ignored"] += 1
            return
        try:
            handler(link, msg)
        except (ValueError, TypeError, OverflowError, AttributeError, UnicodeError) as exc:
            self._counters["rx_malformed"] += 1
            log.debug("rx %s rejected: %s", kind, exc)

    def _targets_me(self, msg: Any) -> bool:
        ok = (msg.target_system in (0, self.options.sysid)) and (msg.target_component in (0, self.options.compid))
        if not ok:
            self._counters["rx_wrong_target"] += 1
        return ok

    def _on_heartbeat(self, link: VehicleLink, msg: Any) -> None:
        link.last_peer_heartbeat_s = self._t_s

    def _on_command_long(self, link: VehicleLink, msg: Any) -> None:
        if self._targets_me(msg):
            params = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7]
            self._command(link, msg, [float(p) for p in params])

    def _on_command_int(self, link: VehicleLink, msg: Any) -> None:
        if self._targets_me(msg):
            params = [msg.param1, msg.param2, msg.param3, msg.param4, msg.x, msg.y, msg.z]
            self._command(link, msg, [float(p) for p in params])

    def _command(self, link: VehicleLink, msg: Any, params: list[float]) -> None:
        """Run a command and ACK it to its sender (after which any reply messages follow)."""
        self._counters["commands"] += 1
        handler = self._command_handlers.get(msg.command)
        result, replies = handler(link, params) if handler else (px4.MAV_RESULT_UNSUPPORTED, [])
        header = msg.get_header()
        ack = mavlink.MAVLink_command_ack_message(msg.command, result, 0, 0, header.srcSystem, header.srcComponent)
        self._send(link, ack)
        for reply in replies:
            self._send(link, reply)
        log.debug("command %d %s -> result %d", msg.command, params, result)

    def _cmd_set_mode(self, link: VehicleLink, p: list[float]) -> tuple[int, list[Any]]:
        name = mode_of_set_mode(p)
        if name is None:
            return px4.MAV_RESULT_UNSUPPORTED, []
        result = self._commander.set_mode(self._t_s, name)
        log.info("DO_SET_MODE %s -> %d", name, result)
        return result, []

    def _cmd_arm_disarm(self, link: VehicleLink, p: list[float]) -> tuple[int, list[Any]]:
        arm, force = int_param(p[0]), int_param(p[1]) == px4.ARM_FORCE_MAGIC
        if arm == 1:
            result = self._commander.arm(self._t_s, force)
        elif arm == 0:
            result = self._commander.disarm(self._t_s, force)
        else:
            result = px4.MAV_RESULT_DENIED
        log.info("%s%s -> %d", "ARM" if arm == 1 else "DISARM", " (forced)" if force else "", result)
        return result, []

    def _cmd_takeoff(self, link: VehicleLink, p: list[float]) -> tuple[int, list[Any]]:
        if self.options.frame == "rover":
            return px4.MAV_RESULT_UNSUPPORTED, []
        home_amsl_m = self.options.home[2] - self._commander.home_ned_m[2]
        altitude_m = p[6] - home_amsl_m if math.isfinite(p[6]) else None
        return self._commander.takeoff(self._t_s, altitude_m), []

    def _stream_of(self, link: VehicleLink, msg_id: int) -> tel.Stream | None:
        return next((s for s in self._streams[link.name].values() if s.msg_id == msg_id), None)

    def _cmd_request_message(self, link: VehicleLink, p: list[float]) -> tuple[int, list[Any]]:
        msg_id = int_param(p[0])
        if msg_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return px4.MAV_RESULT_ACCEPTED, [tel.autopilot_version(self.options.sysid)]
        stream = self._stream_of(link, msg_id)
        if stream is None:
            return px4.MAV_RESULT_DENIED, []  # as PX4 when it cannot send the message
        return px4.MAV_RESULT_ACCEPTED, [tel.build(stream.name, self._telemetry_state(), self._geo, self._noise)]

    def _cmd_set_message_interval(self, link: VehicleLink, p: list[float]) -> tuple[int, list[Any]]:
        """PX4's rules (mavlink_receiver.cpp, and measured on SITL): FAILED for HEARTBEAT, for a
        message it cannot stream, or with param3, param4 or param7 (response target) set; interval
        < 0 stops the stream, 0 (or NaN) restores the default, > 0 sets it (delivered up to the
        stream's source rate). Only the link the command came on changes."""
        msg_id, interval_us = int_param(p[0]), p[1]
        stream = self._stream_of(link, msg_id)
        extras_set = any(math.isfinite(x) and int(x + 0.5) != 0 for x in (p[2], p[3], p[6]))
        if stream is None or msg_id == mavlink.MAVLINK_MSG_ID_HEARTBEAT or extras_set:
            return px4.MAV_RESULT_FAILED, []
        if interval_us < -1e-5:
            rate_hz = 0.0
        elif interval_us > 1e-5:
            rate_hz = 1e6 / interval_us
        else:
            rate_hz = stream.default_rate_hz
        stream.set_rate(rate_hz, self.clock.speed)
        stream.next_due_s = self._t_s
        return px4.MAV_RESULT_ACCEPTED, []

    def _cmd_get_message_interval(self, link: VehicleLink, p: list[float]) -> tuple[int, list[Any]]:
        """MESSAGE_INTERVAL of the stream on this link (PX4: 0 when it is not streamed), sent
        before the ACK as PX4 does."""
        msg_id = int_param(p[0])
        stream = self._stream_of(link, msg_id)
        self._send(link, mavlink.MAVLink_message_interval_message(msg_id, stream.interval_us() if stream else 0))
        return px4.MAV_RESULT_ACCEPTED, []

    def _on_setpoint(self, link: VehicleLink, msg: Any) -> None:
        if not self._targets_me(msg):
            return
        setpoint, reason = setpoint_of(msg, self._kin.yaw_rad)
        if setpoint is None:
            self._counters["setpoints_rejected"] += 1
            self._commander.reject_setpoint(self._t_s, reason)
            return
        self._counters["setpoints_accepted"] += 1
        self._commander.accept_setpoint(self._t_s, setpoint)

    def _on_param_request_list(self, link: VehicleLink, msg: Any) -> None:
        if self._targets_me(msg):
            for index in range(len(self.params)):
                self._send(link, param_value(self.params, self.params.name_at(index)))

    def _on_param_request_read(self, link: VehicleLink, msg: Any) -> None:
        if not self._targets_me(msg):
            return
        try:
            name = self.params.name_at(msg.param_index) if msg.param_index >= 0 else str(msg.param_id)
            self._send(link, param_value(self.params, name))
        except (UnknownParam, KeyError):
            self._counters["rx_ignored"] += 1

    def _on_param_set(self, link: VehicleLink, msg: Any) -> None:
        if not self._targets_me(msg):
            return
        try:
            self.params.set_from_wire(str(msg.param_id), msg.param_value, msg.param_type)
        except (UnknownParam, ValueError):
            self._counters["rx_ignored"] += 1
            return
        self._counters["params_set"] += 1
        log.info("PARAM_SET %s = %g", msg.param_id, self.params.get(str(msg.param_id)))
        self._send(link, param_value(self.params, str(msg.param_id)))

    def _on_timesync(self, link: VehicleLink, msg: Any) -> None:
        if msg.tc1 == 0:
            self._send(link, mavlink.MAVLink_timesync_message(int(self._t_s * 1e9), msg.ts1))
        elif self.options.lockstep and link is self._links[0] and msg.ts1 == self._barrier_ns:
            self._lockstep_answer = int(msg.tc1)  # the controller finished this step

    # ---- sending -------------------------------------------------------------------------
    def _send(self, link: VehicleLink, msg: Any) -> None:
        """Encode ``msg`` on ``link`` and send it through the outbound faults."""
        data = link.pack(msg)
        self._counters["tx_messages"] += 1
        fate, delay_s = self._faults.admit("out", self._t_s)
        if fate == "blackout":
            self._counters["blackout_out"] += 1
        elif fate == "lost":
            self._counters["dropped_out"] += 1
        elif fate == "delay":
            self._counters["delayed_out"] += 1
            self._faults.hold(self._t_s + delay_s, "out", (link, data))
        elif link.target is not None:
            self._emit(link, data)

    def _emit(self, link: VehicleLink, data: bytes) -> None:
        """Send a packet that passed the faults: now (one per datagram, as PX4), or in lockstep
        with the rest of its step (:meth:`_flush_links`), behind the step's SYSTEM_TIME."""
        self._mark_time(link)
        if self._batching:
            link.queue(data)
        elif not link.sendto(data, link.target):  # type: ignore[arg-type]  (the caller checked)
            self._counters["tx_errors"] += 1

    def _flush_links(self) -> None:
        """Send each link's batch of this step as one datagram (lockstep)."""
        for link in self._links:
            self._counters["tx_errors"] += link.flush()

    def _telemetry_state(self) -> tel.TelemetryState:
        c, k = self._commander, self._kin
        return tel.TelemetryState(self._t_s, k, c.mode, c.armed, c.system_status(), c.landed_state(k), c.armable(),
                                  c.position_valid, c.setpoint, c.home_ned_m, FRAMES[self.options.frame])

    def _service_streams(self, t_s: float) -> None:
        state: tel.TelemetryState | None = None
        built: dict[str, Any] = {}  # one message per stream and step, whichever link it goes to
        for link in self._links:
            for stream in self._streams[link.name].values():
                if stream.period_s <= 0 or stream.next_due_s > t_s + DUE_EPSILON:
                    continue
                if stream.name not in built:
                    state = state or self._telemetry_state()
                    built[stream.name] = tel.build(stream.name, state, self._geo, self._noise)
                self._send(link, built[stream.name])
                stream.next_due_s += stream.period_s
                if stream.next_due_s <= t_s:
                    stream.next_due_s = t_s + stream.period_s

    def _flush_outbox(self) -> None:
        """Send the commander's STATUSTEXTs to the links whose peer is alive (PX4 rule)."""
        self._collect_events()
        unsent, self._unsent = self._unsent, []
        for _, severity, text in unsent:
            log.info("STATUSTEXT %s", text)
            self._chunk_id = self._chunk_id % 65535 + 1
            for link in self._links:
                peer_alive = self._t_s - link.last_peer_heartbeat_s <= STATUSTEXT_PEER_TIMEOUT_S
                if peer_alive or not self.options.statustext_needs_heartbeat:
                    for chunk in tel.statustext_chunks(severity, text, self._chunk_id):
                        self._send(link, chunk)


class _StepClock:
    """The lockstep vehicle's own clock: its physics step times [s], advanced by the vehicle."""

    speed = 1.0

    def __init__(self, vehicle: MockVehicle) -> None:
        self._vehicle = vehicle

    def now(self) -> float:
        return self._vehicle._t_s


def _is_timesync(data: bytes) -> bool:
    """Is this datagram a MAVLink 1 or 2 TIMESYNC (id 111)? (Read from the header, before the
    link faults decide its fate.)"""
    if len(data) >= 10 and data[0] == 0xFD:
        return data[7] | data[8] << 8 | data[9] << 16 == mavlink.MAVLINK_MSG_ID_TIMESYNC
    return len(data) >= 6 and data[0] == 0xFE and data[5] == mavlink.MAVLINK_MSG_ID_TIMESYNC


def spawn_process(args: Sequence[str], timeout_s: float = 15.0, **popen_kwargs: Any) -> tuple[subprocess.Popen[bytes], int]:
    """Start ``python -m sim.vehicle_cli ARGS`` as its own process; return it and its UDP port.

    The port comes from ``--port-file`` (added here). Stop the process with ``terminate()``
    (SIGTERM: clean exit 0) and ``wait()``.
    """
    directory = tempfile.mkdtemp(prefix="mock-vehicle-")
    port_file = os.path.join(directory, "port")
    command = [sys.executable, "-m", "sim.vehicle_cli", "--port-file", port_file, *args]
    process = subprocess.Popen(command, **popen_kwargs)
    deadline = time.monotonic() + timeout_s
    try:
        while time.monotonic() < deadline:
            if os.path.exists(port_file):
                with open(port_file, encoding="ascii") as handle:
                    text = handle.read().strip()
                if text.isdigit():
                    return process, int(text)
            if process.poll() is not None:
                raise RuntimeError(f"mock vehicle exited with code {process.returncode} before listening")
            time.sleep(0.02)
        process.kill()
        process.wait()
        raise TimeoutError(f"mock vehicle did not report its port within {timeout_s} s")
    finally:
        if os.path.exists(port_file):
            os.unlink(port_file)
        os.rmdir(directory)
