"""What ``marsupial run`` tells its user: where it listens, what it waits for, phase lines with
both clocks labelled, and what to do after an abort. Formatting only; the CLI prints.

Two clocks appear in a run. The *mission clock* [s] starts when the controller starts (it is the
``t_s`` column of ``record.csv``). The paper's ``t`` [s] starts when riding starts (the first
RIDING tick: the carrier begins its approach with the passenger docked); ``summary.json``, the
demo's table and the plots count from there. Phase lines print the mission clock, and ``t`` once
riding has started.
"""
from __future__ import annotations

import sys
import threading
from typing import Any, Callable, TextIO

from mission.bus.bridge import describe_endpoints, keys
from mission.time.clock import Clock
from mission.config.schema import Config
from mission.phases import Phase
from mission.interfaces import CarrierSource, Vehicle

CLOCKS_NOTE = ("times: [mission X s] = the controller's clock since it started (record.csv t_s); "
               "t = time since the start of riding, the paper's t = 0 (summary.json, plots)")


def startup_lines(cfg: Config, speed: float) -> list[str]:
    k = keys(cfg.zenoh.pair)
    return [
        f"run {cfg.zenoh.pair}: vehicle on MAVLink {cfg.mavlink.url}; carrier state on {k.carrier_state} "
        f"via {describe_endpoints(cfg.zenoh)}; clock x{speed:g}",
        CLOCKS_NOTE,
    ]


def waiting_for(cfg: Config, link: Vehicle, feed: CarrierSource) -> list[str]:
    """What the controller still waits for before it can start (empty: nothing)."""
    missing = []
    st = link.state
    if st.heartbeat_rx_s is None:
        missing.append(f"the vehicle (no HEARTBEAT yet on {cfg.mavlink.url})")
    elif not (st.position_valid and st.position_ned_m is not None):
        missing.append(f"the vehicle's position (HEARTBEAT seen on {cfg.mavlink.url}, no valid LOCAL_POSITION_NED yet)")
    received = feed.latest()
    key = keys(cfg.zenoh.pair).carrier_state
    if received is None:
        missing.append(f"the carrier (no state yet on {key})")
    elif feed.alive is False:
        missing.append(f"the carrier (state seen on {key}, but its liveliness token is gone)")
    elif received.age_s > cfg.mission.carrier_timeout_s:
        missing.append(f"the carrier (its last state on {key} is {received.age_s:.1f} s old)")
    return missing


class WaitReporter:
    """While the mission is in PREFLIGHT, say every ``period_s`` (wall) what it waits for and how
    long until it gives up (``mission.connect_timeout_s``). On a terminal the line is redrawn in
    place; otherwise plain lines."""

    def __init__(self, cfg: Config, controller: Any, link: Vehicle, feed: CarrierSource, clock: Clock,
                 out: TextIO | None = None, period_s: float | None = None) -> None:
        self.cfg, self.controller, self.link, self.feed, self.clock = cfg, controller, link, feed, clock
        self.out = out or sys.stdout
        self.tty = self.out.isatty()
        self.period_s = period_s if period_s is not None else (0.5 if self.tty else 2.0)
        self._done = threading.Event()
        self._drawn = False
        self._thread = threading.Thread(target=self._run, name="run-wait-reporter", daemon=True)

    def start(self) -> "WaitReporter":
        self._thread.start()
        return self

    def stop(self) -> None:
        self._done.set()
        self._thread.join(timeout=2.0)

    def line(self) -> str | None:
        state = self.controller.state
        if state.phase != Phase.PREFLIGHT or state.start_s is None:
            return None
        missing = waiting_for(self.cfg, self.link, self.feed)
        if not missing:
            return None
        limit = self.cfg.mission.connect_timeout_s
        left = max(limit - (self.clock.now() - state.since_s), 0.0)
        speed = float(self.clock.speed)
        wall = "" if speed == 1.0 else f", {left / speed:.1f} s wall at clock x{speed:g}"
        return (f"waiting for {' and '.join(missing)}; giving up in {left:.0f} s{wall} "
                f"(mission.connect_timeout_s = {limit:g} s)")

    def _run(self) -> None:
        wait_s = min(self.period_s, 1.0)  # the first word comes soon, but not before a vehicle could answer
        while not self._done.wait(wait_s):
            wait_s = self.period_s
            text = self.line()
            if text is None:
                if self._drawn and self.tty:
                    self.out.write("\r\033[K")
                    self.out.flush()
                    self._drawn = False
                if self.controller.state.phase != Phase.PREFLIGHT:
                    return
                continue
            if self.tty:
                self.out.write("\r\033[K" + text)
            else:
                self.out.write(text + "\n")
            self.out.flush()
            self._drawn = True

    def clear(self) -> None:
        """Erase a redrawn line before another line is printed."""
        if self._drawn and self.tty:
            self.out.write("\r\033[K")
            self.out.flush()
            self._drawn = False


def event_line(text: str, mission_s: float, riding_start_s: float | None) -> str:
    """A phase line with the mission clock and, once riding has started, t since riding."""
    if riding_start_s is None:
        return f"[mission {mission_s:7.2f} s]             {text}"
    return f"[mission {mission_s:7.2f} s | t {mission_s - riding_start_s:7.2f} s] {text}"


def abort_hint(cfg: Config, detail: str) -> str | None:
    """What to do after an abort the user can fix, or None."""
    limit = cfg.mission.connect_timeout_s
    if detail == "no vehicle":
        return (f"no vehicle answered on MAVLink {cfg.mavlink.url} within {limit:g} s (mission.connect_timeout_s): "
                f"start `marsupial mock-vehicle` (it sends to UDP 14540, like PX4 SITL) or PX4, "
                f"or point --mavlink / mavlink.url at your vehicle")
    if detail == "no carrier":
        return (f"no carrier state on {keys(cfg.zenoh.pair).carrier_state} within {limit:g} s "
                f"(mission.connect_timeout_s), {describe_endpoints(cfg.zenoh)}: start "
                f"`marsupial carrier CONFIG` with the same pair ({cfg.zenoh.pair}) on the same Zenoh network "
                f"(with no endpoints given, both meet on the loopback rendezvous)")
    if detail == "vehicle silent":
        return (f"the vehicle on {cfg.mavlink.url} was heard, then fell silent for over "
                f"{cfg.mission.heartbeat_timeout_s:g} s (mission.heartbeat_timeout_s): check the link and the vehicle")
    if detail == "no vehicle position":
        return (f"the vehicle on {cfg.mavlink.url} sends HEARTBEAT but no valid position within {limit:g} s: "
                f"wait for its estimator (PX4: EKF2 aligned, a local position)")
    return None


def phase_printer(echo: Callable[[str], None]) -> tuple[Callable[[str, str], None], Callable[..., None], dict]:
    """``(on_event, on_start, seen)`` for :func:`mission.cli.run.fly`: phase lines via ``echo``
    with both clocks. ``seen`` collects the controller, clock and riding start."""
    seen: dict[str, Any] = {"riding_start_s": None}

    def on_start(controller: Any, link: Any, feed: Any, clock: Any) -> None:
        seen.update(controller=controller, link=link, feed=feed, clock=clock)

    def on_event(phase: str, text: str) -> None:
        controller = seen.get("controller")
        if controller is None:
            echo(text)
            return
        state = controller.state
        t = state.since_s
        if phase == Phase.RIDING.value and seen["riding_start_s"] is None:
            seen["riding_start_s"] = t
            text += " (t = 0: start of riding)"
        if phase == Phase.SEPARATED.value and state.separation_time_s is not None:
            t = state.separation_time_s  # the latched instant, inside the tick
        reporter = seen.get("reporter")
        if reporter is not None:
            reporter.clear()
        echo(event_line(text, t, seen["riding_start_s"]))

    return on_event, on_start, seen
