"""The mission loop: read the newest states, run the phases, send the setpoint, record.

Wiring only: the decisions are in :mod:`mission.phases` (pure), the law and filter in
:mod:`mission.tick`; this module reads the link and the Zenoh feed, executes vehicle commands
on a worker thread (so arming and mode switches never stall the setpoint stream), and writes
the flight record. The setpoint is sent from the loop itself and from nowhere else: when the
loop stops, the stream stops, and PX4's offboard-loss failsafe sees it.
"""
from __future__ import annotations

import logging
import queue
import threading
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from mission import phases, px4
from mission.clock import Clock, Periodic
from mission.config import Config
from mission.errors import CommandRejected, ConfigError, LinkError
from mission.log import FlightRecorder
from mission.phases import CarrierObs, MissionModel, MissionState, Observation, Phase, VehicleObs
from mission.safety import SafetyConfig
from mission.wire import GeoOrigin, PassengerStatus
from sim.closed_loop import model_from_config

log = logging.getLogger(__name__)

ABORT_GRACE_S = 15.0  # longest the loop keeps asking for Hold after an abort [s]


def mission_model(cfg: Config) -> MissionModel:
    """The phases' fixed parameters from a configuration (3D, local NED)."""
    if cfg.scenario.dim != 3:
        raise ConfigError("scenario.dim", cfg.scenario.dim, "a flight needs dim = 3 (local NED)")
    tick = model_from_config(cfg)
    s = cfg.safety
    ref_speed = s.passenger_max_speed_m_s
    command = SafetyConfig(
        cbf_gain=s.cbf_gain, margin_m=s.margin_m * 0.5,
        max_speed_m_s=None if ref_speed is None else ref_speed * 1.25,
        max_accel_m_s2=None if s.passenger_max_accel_m_s2 is None else s.passenger_max_accel_m_s2 * 1.5,
        z_min_m=s.z_min_m, z_max_m=s.z_max_m,
    )
    m = cfg.mission
    return MissionModel(
        tick=tick, command_safety=command, dock_offset_ned_m=np.asarray(m.dock_offset_ned_m, dtype=float),
        dock_tolerance_m=m.dock_tolerance_m, track_gain=m.track_gain, join_speed_m_s=m.join_speed_m_s,
        arrival_radius_m=m.arrival_radius_m, arrival_dwell_s=m.arrival_dwell_s, final_action=m.final_action,
        carrier_timeout_s=m.carrier_timeout_s, heartbeat_timeout_s=m.heartbeat_timeout_s, prestream_s=m.prestream_s,
        connect_timeout_s=m.connect_timeout_s, max_duration_s=m.max_duration_s, dt_s=1.0 / m.rate_hz,
    )


class CommandWorker:
    """Runs vehicle commands ("arm", "offboard", "hold", "land") one at a time off the loop.

    A request is retried up to ``retries`` times (each try is the link's own ACK/retry cycle);
    then ``failed[request]`` holds the vehicle's reason and the phases decide. Hold and Land may
    be asked again after ``repeat_s`` if the vehicle still does not show the mode.
    """

    ACTIONS = {"arm": "arm", "offboard": "offboard", "hold": "hold", "land": "land"}

    def __init__(self, link: Any, clock: Clock, retries: int = 3, repeat_s: float = 2.0) -> None:
        self.link, self.clock, self.retries, self.repeat_s = link, clock, retries, repeat_s
        self.failed: dict[str, str] = {}
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._busy = threading.Event()
        self._last: dict[str, float] = {}
        self._thread = threading.Thread(target=self._run, name="mission-commands", daemon=True)
        self._thread.start()

    def submit(self, request: str) -> None:
        if self._busy.is_set() or request in self.failed:
            return
        last = self._last.get(request)
        if last is not None and self.clock.now() - last < self.repeat_s:
            return
        self._last[request] = self.clock.now()
        self._busy.set()
        self._queue.put(request)

    def _execute(self, request: str) -> None:
        if request == "arm":
            self.link.arm()
        elif request == "offboard":
            self.link.set_mode("OFFBOARD")
        elif request == "hold":
            self.link.hold()
        elif request == "land":
            self.link.land()

    def _run(self) -> None:
        while True:
            request = self._queue.get()
            if request is None:
                return
            reason = ""
            for attempt in range(1, self.retries + 1):
                try:
                    self._execute(request)
                    log.info("vehicle accepted %s", request)
                    reason = ""
                    break
                except CommandRejected as exc:
                    reason = exc.reason or f"MAV_RESULT {exc.result}"
                except LinkError as exc:
                    reason = str(exc)
                log.warning("%s refused (try %d/%d): %s", request, attempt, self.retries, reason)
                self.clock.sleep(0.5)
            if reason and request in ("arm", "offboard"):
                self.failed[request] = reason
            self._last[request] = self.clock.now()
            self._busy.clear()

    def close(self) -> None:
        self._queue.put(None)
        self._thread.join(timeout=5.0)


@dataclass
class MissionOutcome:
    """How the mission ended: phase (DONE or ABORT), reason and detail, log directory, summary."""

    phase: str
    reason: str
    detail: str
    log_dir: str | None
    summary: dict[str, Any]

    @property
    def ok(self) -> bool:
        return self.phase == Phase.DONE.value


def _vehicle_obs(state: Any) -> VehicleObs | None:
    if state.heartbeat_rx_s is None:
        return None
    pos = state.position_ned_m
    vel = state.velocity_ned_m_s
    return VehicleObs(
        position_ned_m=np.zeros(3) if pos is None else np.asarray(pos, dtype=float),
        velocity_ned_m_s=np.zeros(3) if vel is None else np.asarray(vel, dtype=float),
        armed=state.armed, mode=state.mode, heartbeat_age_s=state.heartbeat_age_s,
        position_valid=bool(state.position_valid and pos is not None),
        position_age_s=float("inf") if state.position_rx_s is None else state.t_s - state.position_rx_s,
        in_failsafe=state.system_status == px4.MAV_STATE_CRITICAL,
    )


def _carrier_obs(received: Any, alive: bool | None) -> CarrierObs | None:
    if received is None:
        return None
    st = received.value
    return CarrierObs(position_ned_m=np.asarray(st.position, dtype=float),
                      velocity_ned_m_s=np.asarray(st.velocity_ned_m_s, dtype=float), age_s=received.age_s, alive=alive)


class MissionController:
    """One mission: ``run()`` ticks at ``mission.rate_hz`` until DONE or ABORT.

    link: a :class:`mission.link.VehicleLink` (opened, vehicle identified or not yet);
    feed: a :class:`mission.carrier_bridge.CarrierFeed`; publisher: a
    :class:`mission.carrier_bridge.PassengerPublisher` (or None); recorder: a
    :class:`mission.log.FlightRecorder` (or None); ``on_event(phase, text)`` is called on every
    phase change and event (the CLI prints them).
    """

    def __init__(self, cfg: Config, link: Any, feed: Any, clock: Clock, *, publisher: Any = None,
                 recorder: FlightRecorder | None = None, on_event: Callable[[str, str], None] | None = None,
                 stop: threading.Event | None = None) -> None:
        self.cfg, self.link, self.feed, self.clock = cfg, link, feed, clock
        self.publisher, self.recorder = publisher, recorder
        self.model = mission_model(cfg)
        self.on_event = on_event or (lambda phase, text: None)
        self.stop = stop or threading.Event()
        self.state = MissionState()
        self.ticks = 0
        self.overruns = 0
        self._seq = 0
        self._origin_given = False

    def _observe(self, t: float, worker: CommandWorker) -> Observation:
        vstate = self.link.state
        if vstate.origin is not None and not self._origin_given:
            self.feed.set_origin(GeoOrigin(*vstate.origin))  # wgs84 carrier states become usable
            self._origin_given = True
        return Observation(t_s=t, vehicle=_vehicle_obs(vstate), carrier=_carrier_obs(self.feed.latest(), self.feed.alive),
                           failed=dict(worker.failed), interrupted=self.stop.is_set())

    def _publish(self, t: float, obs: Observation) -> None:
        if self.publisher is None or obs.vehicle is None:
            return
        self._seq += 1
        st = self.state
        try:
            self.publisher.publish(PassengerStatus(
                phase=st.phase.value, stamp_s=t, seq=self._seq, position_ned_m=obs.vehicle.position_ned_m,
                velocity_ned_m_s=obs.vehicle.velocity_ned_m_s, separated=st.anchor is not None, anchor_ned_m=st.anchor))
        except Exception as exc:  # a bus hiccup must never stop the flight loop
            log.warning("could not publish passenger status: %s", exc)

    def _record(self, t: float, obs: Observation, dec: phases.Decision) -> None:
        if self.recorder is None:
            return
        v, c = obs.vehicle, obs.carrier
        self.recorder.record(
            t, self.state.phase.value, None if v is None else v.position_ned_m, None if v is None else v.velocity_ned_m_s,
            None if c is None else c.position_ned_m, None if c is None else c.velocity_ned_m_s, dec.dock, self.state.x_ref,
            dec.P, dec.relative, dec.desired, dec.setpoint, dec.safety_acted,
            float("nan") if c is None else c.age_s, "" if v is None else v.mode, bool(v is not None and v.armed))

    def run(self) -> MissionOutcome:
        """Fly the mission; returns its outcome (never raises for a vehicle-side failure)."""
        worker = CommandWorker(self.link, self.clock, retries=self.cfg.mission.command_retries)
        periodic = Periodic(self.clock, self.model.dt_s)
        last_phase = None
        try:
            while True:
                t = periodic.wait()
                obs = self._observe(t, worker)
                self.state, dec = phases.step(self.state, obs, self.model)
                if dec.setpoint is not None:
                    sp = np.asarray(dec.setpoint, dtype=float)
                    if np.all(np.isfinite(sp)):
                        self.link.send_velocity_ned(sp)
                    else:  # never reached: the filter's output is finite; refuse rather than send
                        log.error("non-finite setpoint %s withheld", sp)
                if dec.request is not None:
                    worker.submit(dec.request)
                if self.state.phase != last_phase:
                    last_phase = self.state.phase
                    detail = f" ({self.state.reason}: {self.state.detail})" if self.state.phase == Phase.ABORT else ""
                    self.on_event(last_phase.value, f"phase {last_phase.value}{detail}")
                for text in dec.events:
                    log.info(text)
                self._publish(t, obs)
                self._record(t, obs, dec)
                self.ticks += 1
                if phases.finished(self.state, dec):
                    break
                if self.state.phase == Phase.ABORT and t - self.state.since_s > ABORT_GRACE_S:
                    log.error("vehicle did not show Hold within %.0f s of the abort; giving up", ABORT_GRACE_S)
                    break
        finally:
            worker.close()
            self.overruns = periodic.overruns
        return self._outcome()

    def _outcome(self) -> MissionOutcome:
        st = self.state
        summary: dict[str, Any] = {}
        log_dir = None
        if self.recorder is not None:
            info = {"separation_time_s": st.separation_time_s,
                    "anchor_ned_m": None if st.anchor is None else st.anchor.tolist()}
            outcome = {"phase": st.phase.value, "reason": st.reason, "detail": st.detail,
                       "ticks": self.ticks, "loop_overruns": self.overruns}
            summary = self.recorder.close(outcome, info)
            log_dir = str(self.recorder.dir)
        return MissionOutcome(phase=st.phase.value, reason=st.reason, detail=st.detail, log_dir=log_dir, summary=summary)


def mission_info(cfg: Config) -> dict[str, Any]:
    """What ``mission.json`` records about the mission (for summaries and plots)."""
    return {
        "target_ned_m": list(cfg.scenario.target),
        "obstacles": [{"center": o.center, "radius": o.radius} for o in cfg.scenario.obstacles],
        "bc_m": cfg.law.params().separation_distance_m,
        "dock_offset_ned_m": list(cfg.mission.dock_offset_ned_m),
        "dock_tolerance_m": cfg.mission.dock_tolerance_m,
        "arrival_radius_m": cfg.mission.arrival_radius_m,
        "pair": cfg.zenoh.pair,
        "rate_hz": cfg.mission.rate_hz,
    }

