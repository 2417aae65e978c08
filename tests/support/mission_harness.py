"""A whole marsupial pair in one test process, over real sockets.

The mock vehicle (its own threads, real UDP on 127.0.0.1), the carrier simulator (its own Zenoh
session listening on a test-chosen port) and the mission controller (its own Zenoh session and
MAVLink link) step in lockstep on the vehicle's simulated time (``lockstep=False``: on clocks with
the same speed factor). Faults are injected from the test; ``speed`` is the pace of the wall
clock the vehicle and the controller fall back to once one of them stops.
"""
from __future__ import annotations

import contextlib
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

from mission.bus.bridge import open_session
from mission.time.clock import LockstepClock, ScaledClock
from mission.config.schema import Config, load_config, with_overrides
from mission.controller import MissionController, MissionOutcome
from mission.record.info import mission_info
from mission.mavlink.link import VehicleLink
from mission.cli.run import mission_io
from mission.bus.lockstep import ZenohUpstream, clock_keys
from mission.record.recorder import FlightRecorder
from mission.phases import Phase
from sim.robots.carrier import CarrierSim
from sim.vehicle.mock import MockVehicle, VehicleOptions
from sim.net import free_port, wait_for
from tests.conftest import CONFIGS


@dataclass
class Pair:
    cfg: Config
    vehicle: MockVehicle
    link: VehicleLink
    controller: MissionController
    carrier: CarrierSim
    carrier_stop: threading.Event
    carrier_thread: threading.Thread
    log_dir: Path
    endpoint: str = ""  # the carrier's Zenoh listen endpoint (the controller connects to it)
    outcome: MissionOutcome | None = None
    thread: threading.Thread | None = None
    events: list[tuple[float, str]] = field(default_factory=list)

    @property
    def phase(self) -> Phase:
        return self.controller.state.phase

    def wait_phase(self, *phases: Phase, timeout_s: float = 20.0) -> Phase:
        """Wait (wall clock) until the mission is in one of ``phases``; fail on timeout/finish."""
        def reached() -> Phase | None:
            phase = self.phase
            if phase in phases:
                return phase
            if self.thread is not None and not self.thread.is_alive():
                raise AssertionError(f"mission ended in {phase} ({self.controller.state.reason}) before {phases}")
            return None
        return wait_for(reached, timeout_s, f"phase {' or '.join(p.value for p in phases)} (phase is {self.phase.value})")

    def finish(self, timeout_s: float = 30.0) -> MissionOutcome:
        assert self.thread is not None
        self.thread.join(timeout=timeout_s)
        assert not self.thread.is_alive(), f"mission still running in {self.phase}"
        assert self.outcome is not None
        return self.outcome

    def stop_carrier(self) -> None:
        """The carrier stops publishing (its process hangs): its state goes stale."""
        self.carrier_stop.set()
        self.carrier_thread.join(timeout=5.0)


@contextlib.contextmanager
def flying_pair(tmp_path: Path, *, speed: float = 5.0, config: str = "demo.toml", overrides: dict[str, Any] | None = None,
                vehicle: dict[str, Any] | None = None, start: bool = True, lockstep: bool = True,
                both: dict[str, Any] | None = None) -> Iterator[Pair]:
    """``overrides`` change the controller's configuration, ``both`` the controller's and the
    carrier's (e.g. ``zenoh.signing_key_file``)."""
    cfg = with_overrides(load_config(CONFIGS / config), both or {})
    zport = free_port()
    ep = f"tcp/127.0.0.1:{zport}"
    base = {"zenoh.listen": [], "zenoh.connect": [ep], "zenoh.rendezvous": None, "mavlink.url": "udpin:127.0.0.1:0"}
    mcfg = with_overrides(cfg, {**base, **(overrides or {})})
    ccfg = with_overrides(cfg, {"zenoh.listen": [ep], "zenoh.connect": [], "zenoh.rendezvous": None})
    with contextlib.ExitStack() as stack:
        carrier_session = open_session(ccfg.zenoh)
        stack.callback(carrier_session.close)
        cclock = LockstepClock(speed=speed, name="carrier", creator_runs=False) if lockstep else ScaledClock(speed)
        carrier = CarrierSim(ccfg, cclock, carrier_session)
        stack.callback(carrier.close)
        if isinstance(cclock, LockstepClock):
            upstream = ZenohUpstream(cclock, carrier_session, clock_keys(carrier.pair), carrier.passenger,
                                     published=lambda: carrier.seq - 1, auth=carrier.auth)
            stack.callback(upstream.close)
        carrier_stop = threading.Event()
        carrier_thread = threading.Thread(target=carrier.run, args=(carrier_stop,), daemon=True)
        carrier_thread.start()
        stack.callback(carrier_thread.join, 5.0)
        stack.callback(cclock.close)  # the carrier's sleep ends now, whatever the controller does
        stack.callback(carrier_stop.set)
        clock = LockstepClock(speed=speed, name="mission", creator_runs=False) if lockstep else ScaledClock(speed)
        log_dir = tmp_path / "flight"
        recorder = FlightRecorder(log_dir, mission_info(mcfg))
        feed, publisher, link, sources, _ = stack.enter_context(mission_io(mcfg, clock, recorder.tlog_path))
        vopts = {"target": f"127.0.0.1:{link.port}", "speed": speed, "start_ned": tuple(cfg.scenario.carrier_start),
                 "lockstep": lockstep, **(vehicle or {})}
        v = stack.enter_context(MockVehicle(VehicleOptions(**vopts)))
        pair = Pair(cfg=mcfg, vehicle=v, link=link, controller=None, carrier=carrier, carrier_stop=carrier_stop,  # type: ignore[arg-type]
                    carrier_thread=carrier_thread, log_dir=log_dir, endpoint=ep)
        stop = threading.Event()
        pair.controller = MissionController(mcfg, link, feed, clock, publisher=publisher, recorder=recorder,
                                            on_event=lambda p, text: pair.events.append((clock.now(), text)), stop=stop,
                                            sources=sources)

        def fly() -> None:
            pair.outcome = pair.controller.run()

        pair.thread = threading.Thread(target=fly, daemon=True)
        stack.callback(lambda: pair.thread.join(30.0) if pair.thread.is_alive() else None)
        stack.callback(stop.set)
        if start:
            pair.thread.start()
        yield pair
