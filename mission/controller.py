"""The mission loop: read the newest states, run the phases, send the setpoint, record.

Wiring only: the decisions are in :mod:`mission.phases` (pure), the law and filter in
:mod:`mission.core.tick`; this module reads the link and the Zenoh feed, executes vehicle commands
on a worker thread (so arming and mode switches never stall the setpoint stream), and writes
the flight record. The setpoint is sent from the loop itself and from nowhere else: when the
loop stops, the stream stops, and PX4's offboard-loss failsafe sees it.
"""
from __future__ import annotations

import collections
import dataclasses
import logging
import math
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from mission.flight_mode import FlightMode
from mission import phases

from mission.mavlink import px4, receiver
from mission.core.consistent_velocity import PositionConsistentVelocity
from mission.core.setpoint import Setpoint
from mission.time.clock import Clock, Periodic, join_thread, start_thread
from mission.config.schema import Config
from mission.errors import CommandRejected, LinkError
from mission.record import FlightRecorder, TickRow
from mission.mavlink.commander import KEPT_PARAMS, OFFBOARD_LOSS_RETURN, HomeKeeper, ParamKeeper
from mission.mavlink.env import mavlink
from mission.mavlink.telemetry import VehicleState
from mission.model import mission_model
from mission.phases import AbortReason, CarrierObs, Decision, MissionState, Observation, Phase, VehicleObs
from mission.interfaces import CarrierSource, StatusSink, Vehicle
from mission.phases.phase import Request
from mission.bus.wire import GeoOrigin, PassengerStatus

log = logging.getLogger(__name__)

LOCAL_POSITION_NED_ID = mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED
# PX4's onboard-profile streams the mission never reads (stopped with mission.unused_streams = "stop");
# ATTITUDE (100 Hz, the busiest) only gives the yaw, which the passenger's mission does not use
UNUSED_STREAMS = tuple(getattr(mavlink, f"MAVLINK_MSG_ID_{name}") for name in (
    "ATTITUDE", "ATTITUDE_QUATERNION", "GLOBAL_POSITION_INT", "HIGHRES_IMU", "ODOMETRY", "POSITION_TARGET_LOCAL_NED",
    "ATTITUDE_TARGET", "ALTITUDE", "VFR_HUD", "ESTIMATOR_STATUS"))
ABORT_GRACE_S = 15.0  # longest the loop keeps asking for Hold after an abort [s]
EXTENDED_SYS_STATE_ID = mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE
# EXTENDED_SYS_STATE (PX4's land detector) asked at this rate [Hz] (PX4 streams 5 Hz): a forced
# disarm in the air shows as ON_GROUND LNDMC_TRIG_TIME / 3 (0.33 s) after it, so at 10 Hz within
# about 0.43 s, where the 1 Hz HEARTBEAT can take a second (docs/flying-px4.md)
LANDED_STATE_RATE_HZ = 10.0


#: How each request the phases make is carried out on the vehicle (blocking until confirmed).
COMMANDS: dict[Request, Callable[[Vehicle], None]] = {
    Request.ARM: lambda vehicle: vehicle.arm(),
    Request.OFFBOARD: lambda vehicle: vehicle.set_mode(FlightMode.OFFBOARD),
    Request.HOLD: lambda vehicle: vehicle.hold(),
    Request.LAND: lambda vehicle: vehicle.land(),
    Request.DISARM: lambda vehicle: vehicle.disarm(),
}


class CommandWorker:
    """Runs vehicle commands (:class:`Request`) one at a time off the loop.

    A request is retried up to ``retries`` times (each try is the vehicle's own ACK/retry cycle);
    then ``failed[request]`` holds the vehicle's reason and the phases decide. Hold and Land may
    be asked again after ``repeat_s`` if the vehicle still does not show the mode. With
    ``threaded=False`` a request runs inside :meth:`submit` (deterministic unit tests on a
    manual clock); the flight always uses the thread, so commands never stall the setpoints.
    """

    def __init__(self, vehicle: Vehicle, clock: Clock, retries: int = 3, repeat_s: float = 2.0,
                 threaded: bool = True) -> None:
        self.link, self.clock, self.retries, self.repeat_s = vehicle, clock, retries, repeat_s
        self.failed: dict[str, str] = {}
        self._requests: collections.deque[Request | None] = collections.deque()
        self._cond = threading.Condition()
        self._busy = threading.Event()
        self._last: dict[Request, float] = {}
        self._thread: threading.Thread | None = None
        if threaded:
            self._thread = threading.Thread(target=self._run, name="mission-commands", daemon=True)
            self._thread.start()

    def submit(self, request: str) -> None:
        req = Request(request)
        if self._busy.is_set() or req in self.failed:
            return
        last = self._last.get(req)
        if last is not None and self.clock.now() - last < self.repeat_s:
            return
        self._last[req] = self.clock.now()
        self._busy.set()
        if self._thread is None:
            self._handle(req)
        else:
            self._put(req)

    def _put(self, request: Request | None) -> None:
        with self._cond:
            self._requests.append(request)
            self.clock.notify(self._cond)

    def _next(self) -> Request | None:
        """The next request; waits on the clock (so a lockstep clock runs this thread in turn)."""
        with self._cond:
            while not self._requests:
                self.clock.wait(self._cond, math.inf)
            return self._requests.popleft()

    def _run(self) -> None:
        while True:
            request = self._next()
            if request is None:
                return
            self._handle(request)

    def _handle(self, request: Request) -> None:
        reason = ""
        for attempt in range(1, self.retries + 1):
            try:
                COMMANDS[request](self.link)
                log.info("vehicle accepted %s", request)
                reason = ""
                break
            except CommandRejected as exc:
                reason = exc.reason or f"MAV_RESULT {exc.result}"
            except LinkError as exc:
                reason = str(exc)
            log.warning("%s refused (try %d/%d): %s", request, attempt, self.retries, reason)
            self.clock.sleep(0.5)
        if reason and request in (Request.ARM, Request.OFFBOARD):
            self.failed[request.value] = reason
        self._last[request] = self.clock.now()
        self._busy.clear()

    def close(self) -> None:
        if self._thread is not None:
            self._put(None)
            join_thread(self.clock, self._thread, 5.0)


@dataclass
class MissionOutcome:
    """How the mission ended: phase (DONE or ABORT), reason and detail, log directory, summary."""

    phase: Phase
    reason: AbortReason | None
    detail: str
    log_dir: str | None
    summary: dict[str, Any]

    @property
    def ok(self) -> bool:
        return self.phase is Phase.DONE


def _no_stamp() -> int:
    return 0


def _vehicle_obs(state: VehicleState, velocity_fix: PositionConsistentVelocity | None = None) -> VehicleObs | None:
    """The vehicle as the phases see it; with ``velocity_fix`` its velocity made consistent with
    its position (``mission.velocity_bias_tau_s``, :mod:`mission.core.consistent_velocity`), and
    what that took off the estimator's velocity as ``velocity_bias_ned_m_s``."""
    if state.heartbeat_rx_s is None:
        return None
    pos = state.position_ned_m
    vel = state.velocity_ned_m_s
    age = float("inf") if state.position_rx_s is None else state.t_s - state.position_rx_s
    sample_t = state.position_t_s
    bias = None
    if velocity_fix is not None and pos is not None and vel is not None and sample_t is not None:
        raw = np.asarray(vel, dtype=float)
        vel = velocity_fix.update(sample_t, np.asarray(pos, dtype=float), raw)
        bias = raw - vel  # what the estimator's velocity says beyond its position's rate
    if pos is not None and vel is not None and age <= phases.TELEMETRY_SILENT_S and sample_t is not None:
        # The vehicle's position now: its last LOCAL_POSITION_NED moved on by its velocity since
        # the vehicle took it (by its own clock), as the dock point is; a late sample, or a burst
        # of old ones read after a stall, would otherwise count speed x delay as offset.
        ahead = min(max(state.t_s - sample_t, 0.0), phases.TELEMETRY_SILENT_S)
        pos = np.asarray(pos, dtype=float) + np.asarray(vel, dtype=float) * ahead
    return VehicleObs(
        position_ned_m=np.zeros(3) if pos is None else np.asarray(pos, dtype=float),
        velocity_ned_m_s=np.zeros(3) if vel is None else np.asarray(vel, dtype=float),
        armed=state.believed_armed, mode=state.mode, heartbeat_age_s=state.heartbeat_age_s,
        position_valid=bool(state.position_valid and pos is not None),
        position_age_s=age,
        in_failsafe=state.system_status == px4.MAV_STATE_CRITICAL,
        battery_pct=state.battery_pct,
        velocity_bias_ned_m_s=bias,
        on_ground=state.believed_on_ground,
    )


def _carrier_obs(received: Any, alive: bool | None) -> CarrierObs | None:
    if received is None:
        return None
    st = received.value
    return CarrierObs(position_ned_m=np.asarray(st.position, dtype=float),
                      velocity_ned_m_s=np.asarray(st.velocity_ned_m_s, dtype=float), age_s=received.age_s, alive=alive,
                      acceleration_ned_m_s2=st.acceleration_ned_m_s2, yaw_rad=st.yaw_rad,
                      untrusted=getattr(received, "untrusted", None), age_bound_s=getattr(received, "age_bound_s", 0.0))


@dataclass(frozen=True)
class TickReport:
    """What one tick did, for an ``on_tick`` observer (benches, tools): the tick's time on the
    mission clock [s], the phase after it, its decision, the carrier sample it used (or None),
    and CLOCK_MONOTONIC stamps [ns] of the tick's start, the end of its observation, the
    setpoint send call and its return (both 0 when nothing was sent)."""

    t_s: float
    phase: Phase
    decision: Decision
    carrier: Any
    start_ns: int
    observed_ns: int
    send_ns: int
    sent_ns: int


class MissionController:
    """One mission: ``run()`` ticks at ``mission.rate_hz`` until DONE or ABORT.

    link: the :class:`~mission.interfaces.Vehicle` (a :class:`mission.mavlink.link.VehicleLink`, opened,
    vehicle identified or not yet); feed: the :class:`~mission.interfaces.CarrierSource` (a
    :class:`mission.bus.bridge.CarrierFeed`); publisher: a :class:`~mission.interfaces.StatusSink`
    (or None); recorder: a :class:`mission.record.FlightRecorder` (or None). ``on_event(phase,
    text)`` is called on every phase change and event (the CLI prints them), ``on_tick(report)``
    after every tick (:class:`TickReport`; keep it short: it runs in the loop).
    ``command_thread=False`` runs vehicle commands inside the tick (unit tests only).
    """

    def __init__(self, cfg: Config, link: Vehicle, feed: CarrierSource, clock: Clock, *,
                 publisher: StatusSink | None = None, recorder: FlightRecorder | None = None,
                 on_event: Callable[[str, str], None] | None = None, on_tick: Callable[[TickReport], None] | None = None,
                 stop: threading.Event | None = None, command_thread: bool = True) -> None:
        self.cfg, self.link, self.feed, self.clock = cfg, link, feed, clock
        self.publisher, self.recorder = publisher, recorder
        self.model = mission_model(cfg)
        self.on_event = on_event or (lambda phase, text: None)
        self.on_tick = on_tick
        self.stop = stop or threading.Event()
        self.command_thread = command_thread
        self.state = MissionState()
        self.ticks = 0
        self.overruns = 0
        self._seq = 0
        self._origin_given = False
        self._received: Any = None
        self._rates: list[float] = []  # LOCAL_POSITION_NED rate seen each flying tick [Hz]
        self._rate_asked = False
        tau = cfg.mission.velocity_bias_tau_s
        self._velocity_fix = PositionConsistentVelocity(tau) if tau > 0 else None
        self._home: HomeKeeper | None = None
        self._params: ParamKeeper | None = None
        self._px4_asked = False
        self.px4_params: dict[str, Any] = {}  # PX4 parameters read, set and restored (for the summary)
        if recorder is not None:
            recorder.set_counters(self._counters)  # read by the record's sinks, off the loop
        self._doubts_at_separation: int | None = None  # the carrier feed's resyncs + contests when the latch fired

    def _observe(self, t: float, worker: CommandWorker) -> Observation:
        vstate = self.link.state
        if vstate.origin is not None and not self._origin_given:
            self.feed.set_origin(GeoOrigin(*vstate.origin))  # wgs84 carrier states become usable
            self._origin_given = True
        self._received = self.feed.latest()
        failed = dict(worker.failed)
        signing = self.link.signing_problem()
        if signing:
            failed["signing"] = signing  # no vehicle yet, and the reason is the key
        identity = self.link.identity_problem()
        if identity:
            failed["identity"] = identity  # a second autopilot with mavlink.target_system unset
        return Observation(t_s=t, vehicle=_vehicle_obs(vstate, self._velocity_fix), carrier=_carrier_obs(self._received, self.feed.alive_over_interval()),
                           failed=failed, interrupted=self.stop.is_set())

    def _ask_telemetry_rate(self) -> None:
        """Once the preflight checks passed: ask the vehicle for LOCAL_POSITION_NED at ``mission.telemetry_rate_hz``
        (PX4 streams 30 Hz to a 50 Hz loop by default), off the loop. A refusal is logged and the
        mission flies at the rate that comes (the summary's ``position_rate_hz`` says which). Then for
        EXTENDED_SYS_STATE at :data:`LANDED_STATE_RATE_HZ`, and, with ``mission.unused_streams =
        "stop"``, to stop the streams the mission never reads."""
        rate = self.cfg.mission.telemetry_rate_hz
        if self._rate_asked or self.state.phase in (Phase.PREFLIGHT, Phase.ABORT, Phase.DONE):
            return  # after the preflight checks only: a refused start sends the vehicle nothing
        self._rate_asked = True

        def ask() -> None:
            try:
                if rate is not None:
                    self.link.set_message_interval(LOCAL_POSITION_NED_ID, rate)
                    log.info("asked the vehicle for LOCAL_POSITION_NED at %g Hz", rate)
            except (CommandRejected, LinkError) as exc:
                log.warning("vehicle did not take LOCAL_POSITION_NED at %g Hz (%s); flying at the rate it streams", rate, exc)
            try:
                self.link.set_message_interval(EXTENDED_SYS_STATE_ID, LANDED_STATE_RATE_HZ)
            except (CommandRejected, LinkError) as exc:
                log.warning("vehicle did not take EXTENDED_SYS_STATE at %g Hz (%s): a disarm in the air may take up "
                            "to its HEARTBEAT period to notice", LANDED_STATE_RATE_HZ, exc)
            if self.cfg.mission.unused_streams == "stop":
                stopped = 0
                for msg_id in UNUSED_STREAMS:
                    try:
                        self.link.set_message_interval(msg_id, 0.0)
                        stopped += 1
                    except (CommandRejected, LinkError) as exc:  # it streams what it streams
                        log.debug("vehicle did not stop message %d: %s", msg_id, exc)
                log.info("asked the vehicle to stop %d of %d streams the mission does not read", stopped,
                         len(UNUSED_STREAMS))

        start_thread(self.clock, ask, "mission-telemetry-rate")

    def _configure_px4(self) -> None:
        """Once the preflight checks passed, off the loop, for a recovery (``final_action =
        "return"``): PX4's offboard-loss action to Return (``recovery.offboard_loss_return``), so
        that a controller that dies leaves the passenger flying to the home kept at the carrier;
        and a warning if PX4's own battery failsafe (BAT_CRIT_THR) would act before our recall.
        For every mission: the failsafe parameters of
        :data:`~mission.mavlink.commander.KEPT_PARAMS`, as set or found, are kept (read back and
        restored by :class:`HomeKeeper`). docs/recovery.md, "PX4's home"."""
        if self._px4_asked or self.state.phase in (Phase.PREFLIGHT, Phase.ABORT, Phase.DONE):
            return
        self._px4_asked = True
        recovery = self.cfg.mission.final_action == "return"
        reserve_pct = self.cfg.recovery.battery_reserve_pct
        keeper = self._params

        def ask() -> None:
            try:
                if recovery:
                    critical = self.link.get_param("BAT_CRIT_THR")
                    self.px4_params["BAT_CRIT_THR"] = critical
                    if reserve_pct <= 100.0 * critical:
                        log.warning("recovery.battery_reserve_pct %g %% is at or below PX4's BAT_CRIT_THR (%g %%): PX4's "
                                    "own low-battery failsafe may act before the recall", reserve_pct, 100.0 * critical)
                if recovery and self.cfg.recovery.offboard_loss_return:
                    was = self.link.get_param("COM_OBL_RC_ACT")
                    self.px4_params["COM_OBL_RC_ACT"] = {"was": was, "set": was}
                    if was != OFFBOARD_LOSS_RETURN:
                        self.px4_params["COM_OBL_RC_ACT"]["set"] = self.link.set_param("COM_OBL_RC_ACT", OFFBOARD_LOSS_RETURN)
                        log.info("PX4's offboard-loss action COM_OBL_RC_ACT set to Return (was %g) for the recovery", was)
            except LinkError as exc:
                log.warning("PX4's parameters for the recovery not read or set: %s", exc)
            if keeper is None:
                return
            for name in KEPT_PARAMS:
                try:
                    keeper.keep(name, self.link.get_param(name))
                except LinkError as exc:
                    log.warning("PX4's %s not read: it is not kept (%s)", name, exc)

        start_thread(self.clock, ask, "mission-px4-params")

    def _restore_px4(self) -> None:
        """Put back the offboard-loss action :meth:`_configure_px4` changed."""
        entry = self.px4_params.get("COM_OBL_RC_ACT")
        if entry is None or entry["set"] == entry["was"]:
            return
        try:
            entry["restored"] = self.link.set_param("COM_OBL_RC_ACT", entry["was"])
        except LinkError as exc:
            log.warning("PX4's COM_OBL_RC_ACT left at Return: %s", exc)

    def _send(self, setpoint: Setpoint) -> bool:
        """Send the decision's setpoint as it is; False if withheld."""
        if not setpoint.is_finite():  # never reached: the filter's output is finite; refuse rather than send
            log.error("non-finite setpoint %s withheld", setpoint)
            return False
        self.link.send(setpoint)
        return True

    def _publish(self, t: float, obs: Observation) -> None:
        if self.publisher is None or obs.vehicle is None:
            return
        self._seq += 1
        st = self.state
        try:
            self.publisher.publish(PassengerStatus(
                phase=st.phase.value, stamp_s=t, seq=self._seq, position_ned_m=obs.vehicle.position_ned_m,
                velocity_ned_m_s=obs.vehicle.velocity_ned_m_s, separated=st.anchor is not None, anchor_ned_m=st.anchor,
                leg=st.leg, reason=st.reason if st.phase == Phase.ABORT else None, holding=st.held_dock is not None))
        except Exception as exc:  # a bus hiccup must never stop the flight loop
            log.warning("could not publish passenger status: %s", exc)

    def _record(self, t: float, obs: Observation, dec: phases.Decision, events: tuple[str, ...]) -> None:
        if self.recorder is None:
            return
        v, c, st = obs.vehicle, obs.carrier, self.state
        self.recorder.record_row(TickRow(
            t, st.phase.value, None if v is None else v.position_ned_m, None if v is None else v.velocity_ned_m_s,
            None if c is None else c.position_ned_m, None if c is None else c.velocity_ned_m_s, dec.dock, st.x_ref,
            dec.P, dec.relative, dec.desired, dec.setpoint, dec.safety_acted,
            float("nan") if c is None else c.age_s, "" if v is None else v.mode, bool(v is not None and v.armed),
            u_ref=st.u_ref, anchor=st.anchor, course=None if st.recovery is None else st.recovery.course,
            events=events, yaw_c=None if c is None else c.yaw_rad))

    def run(self) -> MissionOutcome:
        """Fly the mission; returns its outcome (never raises for a vehicle-side failure)."""
        worker = CommandWorker(self.link, self.clock, retries=self.cfg.mission.command_retries,
                               threaded=self.command_thread)
        self._params = ParamKeeper(self.link.get_param, self.link.set_param)
        self._home = home = HomeKeeper(self.link, self.clock, threaded=self.command_thread, params=self._params)
        periodic = Periodic(self.clock, self.model.dt_s)
        last_phase = None
        stamp = time.monotonic_ns if self.on_tick is not None else _no_stamp
        try:
            while True:
                t = periodic.wait()
                start_ns = stamp()
                obs = self._observe(t, worker)
                self._ask_telemetry_rate()
                self._configure_px4()
                if self.cfg.mission.telemetry_rate_hz is not None and self.state.phase in phases.FLYING:
                    self._rates.append(self.link.message_rate_hz())
                observed_ns = send_ns = sent_ns = stamp()
                self.state, dec = phases.step(self.state, obs, self.model)
                if dec.setpoint is not None:
                    send_ns = stamp()
                    self._send(dec.setpoint)
                    sent_ns = stamp()
                if dec.request is not None:
                    worker.submit(dec.request)
                home.offer(dec.home_ned_m)
                events = dec.events
                if self.state.phase != last_phase:
                    last_phase = self.state.phase
                    detail = f" ({self.state.reason}: {self.state.detail})" if self.state.phase == Phase.ABORT else ""
                    self.on_event(last_phase.value, f"phase {last_phase.value}{detail}")
                    events = (f"phase {last_phase.value}{detail}", *events)
                for text in dec.events:
                    log.info(text)
                self._publish(t, obs)
                self._record(t, obs, dec, events)
                self._note_separation()
                self.ticks += 1
                if self.on_tick is not None:
                    self.on_tick(TickReport(t, self.state.phase, dec, self._received, start_ns, observed_ns,
                                            send_ns if dec.setpoint is not None else 0,
                                            sent_ns if dec.setpoint is not None else 0))
                if phases.finished(self.state, dec):
                    break
                if self.state.phase == Phase.ABORT and t - self.state.since_s > ABORT_GRACE_S:
                    log.error("vehicle did not show Hold within %.0f s of the abort; giving up", ABORT_GRACE_S)
                    break
        finally:
            worker.close()
            home.close()
            self._restore_px4()
            self.overruns = periodic.overruns
        return self._outcome()

    def _note_separation(self) -> None:
        """At the tick the latch fired: how often the carrier feed had jumped onto a new track (a
        resync beyond the carrier's limits) or had its source contested by then (the separation
        may rest on such a track)."""
        if self._doubts_at_separation is None and self.state.anchor is not None:
            c = getattr(self.feed, "counters", None)
            self._doubts_at_separation = int(c.get("jumps", 0) + c.get("contests", 0)) if isinstance(c, dict) else 0

    def _counters(self) -> dict[str, Any]:
        """What was dropped and why, for summary.json: the carrier feed's counters (received,
        accepted, dropped per reason, bound and rejected sources, resyncs), the link's, the
        per-packet log lines held back by kind (:mod:`mission.mavlink.receiver`), and in lockstep
        the clock's (barriers, fall-back, carriers dropped as silent)."""
        out: dict[str, Any] = {"carrier_feed": self.feed.counters, "link": dataclasses.asdict(self.link.counters),
                               "log_lines_held": receiver.LIMITER.suppressed(),
                               "home": None if self._home is None else self._home.counters, "px4_params": self.px4_params,
                               "px4_kept": None if self._params is None else {
                                   "values": dict(self._params.kept), **self._params.counters, "moves": list(self._params.moves)}}
        if self.clock.counters is not None:  # a lockstep clock's: was every step in step?
            out["lockstep"] = self.clock.counters
        return out

    def _outcome(self) -> MissionOutcome:
        st = self.state
        summary: dict[str, Any] = {}
        log_dir = None
        if self.recorder is not None:
            info = {"separation_time_s": st.separation_time_s,
                    "anchor_ned_m": None if st.anchor is None else st.anchor.tolist(),
                    "recovered": recovered_info(st), "legs_done": list(st.legs_done), "legs_skipped": st.legs_skipped}
            outcome = {"phase": st.phase, "reason": st.reason, "detail": st.detail,
                       "ticks": self.ticks, "loop_overruns": self.overruns, **self._counters(),
                       "position_rate_hz": round(float(np.median(self._rates)), 2) if self._rates else None,
                       "carrier_resync_before_separation": None if self._doubts_at_separation is None
                       else self._doubts_at_separation > 0}
            if self._doubts_at_separation:  # the latch may have fired on a relocalised (or spoofed) track
                outcome.update(p1=None, p2=None, p3=None, p1_p3_note=(
                    "not claimed: the carrier feed jumped onto a new track or its source was contested before "
                    "the separation (carrier_feed.jumps, carrier_feed.contests)"))
            summary = self.recorder.close(outcome, info)
            log_dir = str(self.recorder.dir)
        return MissionOutcome(phase=st.phase, reason=st.reason, detail=st.detail, log_dir=log_dir, summary=summary)


def recovered_info(st: MissionState) -> dict[str, Any] | None:
    """How the recovery went, for mission.json (None: the mission did not try one)."""
    rec = st.recovery
    if rec is None:
        return None
    return {"why": rec.why, "attempts": rec.attempts, "contact": rec.contact, "fallback": rec.fallback_why or None,
            "started_s": rec.started_s}


def mission_info(cfg: Config) -> dict[str, Any]:
    """What ``mission.json`` records about the mission (for summaries and plots)."""
    return {
        "target_ned_m": list(cfg.scenario.target),
        "obstacles": [{"center": o.center, "radius": o.radius} for o in cfg.scenario.obstacles],
        "bc_m": cfg.law.params().separation_distance_m,
        "carrier_start_ned_m": list(cfg.scenario.carrier_start),
        "dock_offset_ned_m": list(cfg.mission.dock_offset_ned_m),
        "dock_tolerance_m": cfg.mission.dock_tolerance_m,
        "arrival_radius_m": cfg.mission.arrival_radius_m,
        "pair": cfg.zenoh.pair,
        "rate_hz": cfg.mission.rate_hz,
        "final_action": cfg.mission.final_action,
        "ride": cfg.mission.ride,
        "deck_clear_height_m": cfg.mission.deck_clear_height_m,
        "targets": cfg.scenario.legs(),
        "frame": cfg.scenario.frame,
        "recovery": cfg.recovery.model_dump(mode="json") if cfg.mission.final_action == "return" else None,
    }

