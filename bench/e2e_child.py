"""The controller process of the end-to-end bench (``python -m bench.e2e_child``; internal).

It runs the real :class:`~mission.controller.MissionController` with ``marsupial run``'s wiring
(:func:`mission.cli.run.mission_io`: VehicleLink, CarrierFeed, PassengerPublisher,
FlightRecorder) on the demo configuration at the asked rate, and records every tick that sent a
setpoint through the controller's ``on_tick`` observer: when the tick started, when its
observation ended, which carrier sample it used (``seq`` and when the feed's Zenoh callback
received it), and when ``send`` was called and returned. Its clock is
CLOCK_MONOTONIC at speed 1; stamps are converted to CLOCK_REALTIME with an offset sampled at
start (the two do not drift apart measurably in a run of seconds). It prints ``PORT <n> <live>`` (the
link's UDP port; the live server's TCP port, or 0) first, then writes its record as JSON to ``--out``.
``--flight-data`` adds flight.mcap, or flight.mcap and the live server, to the record.
"""
from __future__ import annotations

import json
import resource
import threading
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import click

from mission.time.monotonic import MonotonicClock

ROOT = Path(__file__).resolve().parents[1]
DEMO_CONFIG = ROOT / "configs" / "demo.toml"
PAIR = "bench"
WARMUP_S = 0.3  # of RIDING, not measured [s]


def realtime_offset_ns() -> int:
    """CLOCK_REALTIME - CLOCK_MONOTONIC [ns], from the tightest of 50 brackets."""
    best = None
    for _ in range(50):
        m0 = time.monotonic_ns()
        r = time.time_ns()
        m1 = time.monotonic_ns()
        if best is None or m1 - m0 < best[0]:
            best = (m1 - m0, r - (m0 + m1) // 2)
    assert best is not None
    return best[1]


class RealtimeMonotonicClock(MonotonicClock):
    """The controller's clock here: :class:`mission.time.clock.MonotonicClock`, whose times and
    stamps also convert to CLOCK_REALTIME [ns] (the kernel's receive stamps are realtime)."""

    def __init__(self) -> None:
        self._offset_ns = realtime_offset_ns()
        super().__init__()

    def real_ns(self, t_s: float) -> int:
        """CLOCK_REALTIME [ns] of clock time ``t_s`` [s]."""
        return self.to_monotonic_ns(t_s) + self._offset_ns

    def real_of_monotonic_ns(self, monotonic_ns: int) -> int:
        return monotonic_ns + self._offset_ns

    def real_now_ns(self) -> int:
        return time.monotonic_ns() + self._offset_ns


class SendLog:
    """The ``on_tick`` observer: one row per tick that sent a setpoint (a list of tuples: cheap).

    Row: [tick start, seq used, its receipt, send returned, send time on the link clock [ms],
    riding, observation done, send called]; times [ns] CLOCK_REALTIME.
    """

    def __init__(self, clock: RealtimeMonotonicClock) -> None:
        self.clock = clock
        self.rows: list[tuple[int, int, int, int, int, bool, int, int]] = []
        # every tick: [start [ns] realtime, start -> on_tick [ns], the loop thread's CPU time since the
        # previous on_tick [ns] (one period: its wait, nearly free, and the tick; other processes excluded)]
        self.ticks: list[tuple[int, int, int]] = []
        self._cpu_ns: int | None = None
        self._seq, self._rx_s = -1, 0.0

    def __call__(self, report: Any) -> None:
        cpu = time.thread_time_ns()
        self.ticks.append((self.clock.real_of_monotonic_ns(report.start_ns), time.monotonic_ns() - report.start_ns,
                           0 if self._cpu_ns is None else cpu - self._cpu_ns))
        self._cpu_ns = cpu
        if report.carrier is not None:  # the sample stays "used" until a newer one arrives
            self._seq, self._rx_s = report.carrier.value.seq, report.carrier.rx_time_s
        if not report.send_ns:
            return
        c = self.clock
        self.rows.append((c.real_of_monotonic_ns(report.start_ns), self._seq, c.real_ns(self._rx_s),
                          c.real_of_monotonic_ns(report.sent_ns), int(c.from_monotonic_ns(report.sent_ns) * 1000),
                          report.phase.value == "RIDING", c.real_of_monotonic_ns(report.observed_ns),
                          c.real_of_monotonic_ns(report.send_ns)))


def child_main(rate_hz: float, duration_s: float, zenoh_connect: str, log_dir: str, out: str,
               profile: str = "", flight_data: str = "none") -> None:
    """The controller process: ``marsupial run``'s wiring with the tick observer.

    ``flight_data``: "none" (record.csv only), "mcap" (and flight.mcap, as ``marsupial run``),
    "live" (and the live server on a free loopback port, printed as ``LIVE <port>``)."""
    from mission.config.schema import load_config, with_overrides
    from mission.controller import MissionController
    from mission.record.info import mission_info
    from mission.flightdata.writer import LiveAddress
    from mission.record.recorder import FlightRecorder
    from mission.cli.run import flight_data as flight_data_sinks, mission_io

    cfg = with_overrides(load_config(DEMO_CONFIG), {
        "mission.rate_hz": rate_hz, "mission.max_duration_s": duration_s + 120.0, "zenoh.pair": PAIR,
        "zenoh.listen": [], "zenoh.connect": [zenoh_connect], "mavlink.url": "udpin:127.0.0.1:0"})
    clock = RealtimeMonotonicClock()
    sends = SendLog(clock)
    stop = threading.Event()
    window: dict[str, Any] = {}
    with ExitStack() as stack:
        info, directory = mission_info(cfg), Path(log_dir) / "flight"
        live = LiveAddress("127.0.0.1", 0) if flight_data == "live" else None
        sinks = flight_data_sinks(cfg, directory, info, clock, live) if flight_data != "none" else []
        recorder = FlightRecorder(directory, info, sinks)
        feed, publisher, link, sources, _ = stack.enter_context(mission_io(cfg, clock, recorder.tlog_path))
        controller = MissionController(cfg, link, feed, clock, publisher=publisher, recorder=recorder, stop=stop,
                                       on_tick=sends, sources=sources)
        live_port = next((s.live_port for s in sinks if getattr(s, "live_port", None) is not None), 0)
        print(f"PORT {link.port} {live_port}", flush=True)

        def measure_window() -> None:
            deadline = time.monotonic() + 30.0
            while controller.state.phase.value != "RIDING":
                if time.monotonic() > deadline or controller.state.phase.value in ("ABORT", "DONE"):
                    stop.set()
                    return
                time.sleep(0.001)
            time.sleep(WARMUP_S)
            window["start"] = (clock.real_now_ns(), time.process_time(), controller.ticks)
            time.sleep(duration_s)
            window["end"] = (clock.real_now_ns(), time.process_time(), controller.ticks)
            stop.set()

        watcher = threading.Thread(target=measure_window, daemon=True)
        watcher.start()
        if profile:
            import cProfile

            profiler = cProfile.Profile()
            outcome = profiler.runcall(controller.run)
            profiler.dump_stats(profile)
        else:
            outcome = controller.run()
        watcher.join(timeout=5.0)
        counters = link.counters
    if "end" not in window:
        raise SystemExit(f"the controller never rode steadily: {outcome.phase} {outcome.reason} {outcome.detail}")
    (s_ns, s_cpu, s_ticks), (e_ns, e_cpu, e_ticks) = window["start"], window["end"]
    wall_s = (e_ns - s_ns) / 1e9
    result = {
        "sends": sends.rows,
        "ticks": sends.ticks,
        "window_ns": [s_ns, e_ns],
        "wall_s": wall_s,
        "cpu_share": (e_cpu - s_cpu) / wall_s,
        "loop_hz": (e_ticks - s_ticks) / wall_s,
        "overruns": controller.overruns,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,  # Linux: KiB
        "tx_setpoints": counters.tx_setpoints,
        "outcome": f"{outcome.phase} {outcome.reason}",
        "feed": feed.counters,
    }
    Path(out).write_text(json.dumps(result))


@click.command()
@click.option("--rate", type=float, default=50.0, show_default=True, help="Controller rate [Hz].")
@click.option("--duration", type=float, default=5.0, show_default=True, help="Measured RIDING time [s].")
@click.option("--zenoh-connect", required=True, help="Zenoh endpoint of the bench's carrier session.")
@click.option("--log-dir", required=True, type=click.Path(file_okay=False), help="Flight record directory.")
@click.option("--out", required=True, type=click.Path(dir_okay=False), help="Where to write the record (JSON).")
@click.option("--profile", default="", help="Write cProfile statistics of the loop here.")
@click.option("--flight-data", type=click.Choice(["none", "mcap", "live"]), default="none", show_default=True,
              help="Beside record.csv: nothing, flight.mcap, or flight.mcap and the live server.")
def main(rate: float, duration: float, zenoh_connect: str, log_dir: str, out: str, profile: str, flight_data: str) -> None:
    """Run the controller for the end-to-end bench (internal: started by bench.e2e)."""
    child_main(rate, duration, zenoh_connect, log_dir, out, profile, flight_data)


if __name__ == "__main__":
    main()
