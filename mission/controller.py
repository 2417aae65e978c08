"""The mission loop: read the newest states, call the passenger's step, send the setpoint, record.

I/O only: the whole decision is the pure :class:`mission.passenger.step.PassengerStep` (the
observation, the phases, the law and the filters); this module reads the link and the Zenoh feed,
has the vehicle's commands carried out off the loop (:mod:`mission.mavlink.requests`, so arming
and mode switches never stall the setpoint stream), publishes the passenger's status and writes
the flight record. The setpoint is sent from the loop itself and from nowhere else: when the
loop stops, the stream stops, and PX4's offboard-loss failsafe sees it.
"""
from __future__ import annotations

import dataclasses
import logging
import threading
import time
from dataclasses import dataclass
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from mission import phases
from mission.bus.wire import GeoOrigin, PassengerStatus
from mission.config.schema import Config
from mission.core.safety import Neighbours
from mission.core.setpoint import Setpoint
from mission.interfaces import CarrierSource, CountsReadings, MeasurementSource, StatusSink, Vehicle
from mission.mavlink import receiver
from mission.mavlink.commander import HomeKeeper, ParamKeeper
from mission.mavlink.requests import CommandWorker, Px4Setup
from mission.mavlink.telemetry import vehicle_report
from mission.model import mission_model
from mission.passenger.inputs import PassengerInputs
from mission.passenger.relative import shared_bias
from mission.passenger.step import PassengerStep, observe_carrier
from mission.passenger.target import deck_target
from mission.phases import AbortReason, Decision, Measurement, MissionState, Observation, Phase
from mission.record.info import flown_info, outcome_summary
from mission.record.recorder import FlightRecorder
from mission.record.table import TickRow
from mission.time.clock import Clock, Periodic
from mission.time.rate import RateGate

log = logging.getLogger(__name__)

ABORT_GRACE_S = 15.0  # longest the loop keeps asking for Hold after an abort [s]


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


def as_neighbours(heard: Sequence[Any]) -> Neighbours | None:
    """The teammates a :class:`~mission.bus.neighbours.NeighbourFeed` heard (its ``heard()``) as
    the step's :class:`~mission.core.safety.Neighbours` (None: none heard), with what the recovery
    queue reads: each one's phase, recovery time and battery as shared, its system id and its
    leg's target from the team's file (each None where not known: a target not known is the
    queue's safe side, :func:`mission.phases.queue.served`)."""
    if not heard:
        return None
    targets = [m.target_ned_m for m in heard]
    ids = [m.system_id for m in heard]
    return Neighbours(np.array([m.position_ned_m for m in heard], dtype=float),
                      np.array([m.velocity_ned_m_s for m in heard], dtype=float),
                      np.array([m.age_s for m in heard], dtype=float), tuple(m.phase for m in heard),
                      recovery_s=tuple(m.recovery_s for m in heard), battery_pct=tuple(m.battery_pct for m in heard),
                      ids=None if any(i is None for i in ids) else tuple(ids),
                      targets_ned_m=None if any(t is None for t in targets) else np.array(targets, dtype=float))


def _no_stamp() -> int:
    return 0


@dataclass(frozen=True)
class TickReport:
    """What one tick did, for an ``on_tick`` observer (benches, tools): the tick's time on the
    mission clock [s], the phase after it, its decision, the carrier sample it used (or None),
    and CLOCK_MONOTONIC stamps [ns] of the tick's start, the end of its reading (the link, the
    feed; the passenger's step follows, its observation included), the setpoint send call and its return (both 0 when nothing was sent)."""

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
    (or None); recorder: a :class:`mission.record.recorder.FlightRecorder` (or None); sources: the
    measurement feeds (:class:`~mission.interfaces.MeasurementSource`, opened and closed by the
    caller), each polled once a tick, their readings handed to the step as they are. ``on_event(phase,
    text)`` is called on every phase change and event (the CLI prints them), ``on_tick(report)``
    after every tick (:class:`TickReport`; keep it short: it runs in the loop).
    ``command_thread=False`` runs vehicle commands inside the tick (unit tests only).
    ``neighbours``: a team's passenger's teammates (:class:`~mission.bus.neighbours.NeighbourFeed`,
    its ``neighbours()`` read once a tick into :attr:`PassengerInputs.neighbours`; None: no team).
    The carrier's announced target (its state's ``target_ned_m``) goes into
    :attr:`PassengerInputs.carrier_target_ned_m` as it arrived.
    """

    def __init__(self, cfg: Config, link: Vehicle, feed: CarrierSource, clock: Clock, *,
                 publisher: StatusSink | None = None, recorder: FlightRecorder | None = None,
                 on_event: Callable[[str, str], None] | None = None, on_tick: Callable[[TickReport], None] | None = None,
                 stop: threading.Event | None = None, command_thread: bool = True,
                 sources: Sequence[MeasurementSource] = (), neighbours: Any = None) -> None:
        self.cfg, self.link, self.feed, self.clock = cfg, link, feed, clock
        self.neighbours = neighbours
        self._closest: dict[str, Any] = {"distance_m": None, "t_s": None, "phases": None}  # to a teammate, as heard
        self.sources = tuple(sources)
        self._source_failed: set[int] = set()  # the sources whose poll raised (logged once each)
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
        self.step = PassengerStep(self.model, cfg.mission.velocity_bias_tau_s,
                                  cfg.mission.near_deck_velocity_bias_tau_s)
        self._target_gate = RateGate(cfg.relnav.landing_target_rate_hz if cfg.relnav.enabled else 0.0)
        self._target_failed = False  # a LANDING_TARGET send raised (logged once)
        self._home: HomeKeeper | None = None
        self._params: ParamKeeper | None = None
        self.px4_params: dict[str, Any] = {}  # PX4 parameters read, set and restored (for the summary)
        if recorder is not None:
            recorder.set_counters(self._counters)  # read by the record's sinks, off the loop
        self._doubts_at_separation: int | None = None  # the carrier feed's resyncs + contests when the latch fired

    def _read(self, t: float, worker: CommandWorker) -> PassengerInputs:
        """The tick's raw observations: the link's vehicle, the feed's newest carrier, the measurement
        feeds' readings, what failed."""
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
        mates = None if self.neighbours is None else as_neighbours(self.neighbours.heard())
        vehicle = vehicle_report(vstate)
        self._note_closest(t, vehicle, mates)
        return PassengerInputs(t_s=t, vehicle=vehicle,
                               carrier=observe_carrier(self._received, self.feed.alive_over_interval()),
                               failed=failed, interrupted=self.stop.is_set(), measurements=self._poll(t),
                               neighbours=mates, carrier_target_ned_m=getattr(
                                   getattr(self._received, "value", None), "target_ned_m", None))

    def _note_closest(self, t: float, vehicle: Any, mates: Any) -> None:
        """The least distance [m] so far between this passenger's reported position and a
        teammate's, moved on by its age (one no older than the barrier's limit), while either of
        them flies (:data:`mission.phases.FLYING`; two on the deck stand where their slots are),
        for the summary."""
        if mates is None or vehicle is None or vehicle.position_ned_m is None:
            return
        positions, _, fresh = mates.now(self.cfg.safety.passenger_separation_max_age_s)
        gaps = np.linalg.norm(positions - np.asarray(vehicle.position_ned_m)[None, :], axis=-1)
        if fresh is not None:
            gaps = np.where(fresh, gaps, np.inf)
        flying = [self.state.phase in phases.FLYING or (p is not None and Phase[p] in phases.FLYING)
                  for p in (mates.phases or (None,) * len(gaps))]
        gaps = np.where(flying, gaps, np.inf)
        k = int(np.argmin(gaps))
        best = self._closest["distance_m"]
        if np.isfinite(gaps[k]) and (best is None or gaps[k] < best):
            self._closest = {"distance_m": round(float(gaps[k]), 4), "t_s": round(t, 3),
                             "phases": [self.state.phase.value, None if mates.phases is None else mates.phases[k]]}

    def _poll(self, t: float) -> tuple[Measurement, ...]:
        """Every measurement feed's readings since the last tick; a feed that raises gives none
        (logged once): a sensor's fault must never stop the setpoint stream."""
        out: list[Measurement] = []
        for i, source in enumerate(self.sources):
            try:
                out.extend(source.poll(t))
            except Exception as exc:
                if i not in self._source_failed:
                    self._source_failed.add(i)
                    log.warning("measurement feed %s failed, its readings are skipped: %s", type(source).__name__, exc)
        return tuple(out)

    def _send(self, setpoint: Setpoint) -> bool:
        """Send the decision's setpoint as it is; False if withheld."""
        if not setpoint.is_finite():  # never reached: the filter's output is finite; refuse rather than send
            log.error("non-finite setpoint %s withheld", setpoint)
            return False
        self.link.send(setpoint)
        return True

    def _offer_landing_target(self, t: float, inputs: PassengerInputs, obs: Observation) -> None:
        """While the relative estimate of the deck is converged and the vehicle's position is valid,
        send the vehicle the deck's landing point (:func:`mission.passenger.target.deck_target`:
        its own position sample plus the estimate, at the sample's time) at
        ``relnav.landing_target_rate_hz``, for PX4's own precision landing (docs/px4-precland.md).
        A send that raises is logged once and never stops the loop."""
        rel, v = obs.relative, inputs.vehicle
        if rel is None or not rel.converged or v is None or not v.valid or v.position_ned_m is None \
                or not self._target_gate.due(t):
            return
        target = deck_target(v.position_ned_m, rel.position_ned_m, self.model.dock_offset_ned_m,
                             t if v.sample_t_s is None else v.sample_t_s, None if obs.carrier is None else obs.carrier.yaw_rad)
        if target is None:
            return
        try:
            self.link.send_landing_target(target)
        except Exception as exc:  # the backstop's message must never stop the setpoint stream
            if not self._target_failed:
                self._target_failed = True
                log.warning("LANDING_TARGET not sent: %s", exc)

    def _publish(self, t: float, obs: Observation) -> None:
        if self.publisher is None or obs.vehicle is None:
            return
        self._seq += 1
        st = self.state
        shared = shared_bias(obs.relative)  # the frames' bias, for the carrier's P3 guard (None: not shared)
        try:
            self.publisher.publish(PassengerStatus(
                phase=st.phase.value, stamp_s=t, seq=self._seq, position_ned_m=obs.vehicle.position_ned_m,
                velocity_ned_m_s=obs.vehicle.velocity_ned_m_s, separated=st.anchor is not None, anchor_ned_m=st.anchor,
                leg=st.leg, reason=st.reason if st.phase == Phase.ABORT else None, holding=st.held_dock is not None,
                **self._queue_fields(t, obs), bias_ned_m=None if shared is None else shared[0],
                bias_sigma_m=None if shared is None else shared[1]))
        except Exception as exc:  # a bus hiccup must never stop the flight loop
            log.warning("could not publish passenger status: %s", exc)

    def _queue_fields(self, t: float, obs: Observation) -> dict[str, float | None]:
        """A team's passenger's share of the recovery queue (its teammates read it): how long its
        recovery has run [s] and its battery [%]; nothing for a single pair (its bytes unchanged)."""
        if self.neighbours is None:
            return {}
        rec, v = self.state.recovery, obs.vehicle
        return {"recovery_s": None if rec is None else max(t - rec.started_s, 0.0),
                "battery_pct": None if v is None or v.battery_pct is None else min(max(float(v.battery_pct), 0.0), 100.0)}

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
            events=events, yaw_c=None if c is None else c.yaw_rad,
            vehicle_age_s=float("nan") if v is None else v.position_age_s, relnav=obs.relative))

    def run(self) -> MissionOutcome:
        """Fly the mission; returns its outcome (never raises for a vehicle-side failure)."""
        worker = CommandWorker(self.link, self.clock, retries=self.cfg.mission.command_retries,
                               threaded=self.command_thread)
        self._params = ParamKeeper(self.link.get_param, self.link.set_param)
        self._home = home = HomeKeeper(self.link, self.clock, threaded=self.command_thread, params=self._params)
        m = self.cfg.mission
        px4_setup = Px4Setup(self.link, self.clock, telemetry_rate_hz=m.telemetry_rate_hz,
                             stop_unused=m.unused_streams == "stop", recovery=m.final_action == "return",
                             battery_reserve_pct=self.cfg.recovery.battery_reserve_pct,
                             offboard_loss_return=self.cfg.recovery.offboard_loss_return, keeper=self._params,
                             params=self.px4_params,
                             precland=self.cfg.relnav.enabled and self.cfg.relnav.landing_target_rate_hz > 0,
                             rangefinder="rangefinder" in m.feeds)
        periodic = Periodic(self.clock, self.model.dt_s)
        last_phase = None
        stamp = time.monotonic_ns if self.on_tick is not None else _no_stamp
        try:
            while True:
                t = periodic.wait()
                start_ns = stamp()
                inputs = self._read(t, worker)
                if self.state.phase not in (Phase.PREFLIGHT, Phase.ABORT, Phase.DONE):
                    px4_setup.start()  # after the preflight checks only: a refused start sends the vehicle nothing
                if m.telemetry_rate_hz is not None and self.state.phase in phases.FLYING:
                    self._rates.append(self.link.message_rate_hz())
                observed_ns = send_ns = sent_ns = stamp()
                result = self.step(self.state, inputs)
                self.state, dec, obs = result.state, result.decision, result.observation
                if dec.setpoint is not None:
                    send_ns = stamp()
                    self._send(dec.setpoint)
                    sent_ns = stamp()
                if dec.request is not None:
                    worker.submit(dec.request)
                self._offer_landing_target(t, inputs, obs)
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
            px4_setup.restore()
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
        per-packet log lines held back by kind (:mod:`mission.mavlink.receiver`), the measurement
        feeds' that keep any, and in lockstep the clock's (barriers, fall-back, carriers dropped as silent)."""
        out: dict[str, Any] = {"carrier_feed": self.feed.counters, "link": dataclasses.asdict(self.link.counters),
                               "log_lines_held": receiver.LIMITER.suppressed(),
                               "home": None if self._home is None else self._home.counters, "px4_params": self.px4_params,
                               "px4_kept": None if self._params is None else {
                                   "values": dict(self._params.kept), **self._params.counters, "moves": list(self._params.moves)}}
        feeds = {name: src.counters for name, src in zip(self.cfg.mission.feeds, self.sources)
                 if isinstance(src, CountsReadings)}
        if feeds:  # the measurement feeds' own (the marker feed: frames read, refused, detected)
            out["feeds"] = feeds
        if self.neighbours is not None:  # a team's passenger: its teammates heard, and the closest one came
            out["neighbours"] = {**self.neighbours.counters, "closest": dict(self._closest)}
        if self.clock.counters is not None:  # a lockstep clock's: was every step in step?
            out["lockstep"] = self.clock.counters
        return out

    def _outcome(self) -> MissionOutcome:
        st = self.state
        summary: dict[str, Any] = {}
        log_dir = None
        if self.recorder is not None:
            outcome = outcome_summary(st, self.ticks, self.overruns, self._counters(), self._rates,
                                      self._doubts_at_separation)
            summary = self.recorder.close(outcome, flown_info(st))
            log_dir = str(self.recorder.dir)
        return MissionOutcome(phase=st.phase, reason=st.reason, detail=st.detail, log_dir=log_dir, summary=summary)
