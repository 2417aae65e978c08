"""The integrated demo as a benchmark (``bench`` sections demo and memory).

``marsupial demo`` (:func:`sim.demo.run_demo`: mock vehicle, carrier simulator and ``marsupial
run`` as three processes over UDP and Zenoh, plus the demo's Zenoh router in this process) at a
given speed factor. Measured per run:

* wall time of the whole run (process start-up included) and the simulated time the mission
  recorded (first to last tick of its flight record), hence the real-time factor achieved;
* P1-P3 and the mission's end (phase, reason, exit code) from its summary, and its loop overruns;
* offboard loss: the mock vehicle says "Failsafe activated" in a STATUSTEXT when the setpoint
  stream lapses for COM_OF_LOSS_T; the controller's link logs every received packet in the
  flight's ``.tlog``, which is searched for it. A mission that aborts (e.g. pilot_override,
  which is what PX4's failsafe mode switch looks like to the controller) also counts;
* peak memory of the controller process: VmHWM (peak resident set) of the ``marsupial run``
  child, read from ``/proc`` every 50 ms while it runs (Linux; None elsewhere).
"""
from __future__ import annotations

import tempfile
import threading
import time
from pathlib import Path

from mission.record.table import read_record
from sim.demo import DEFAULT_CONFIG, run_demo


class PeakRss:
    """Watches this process's children whose command line holds all of ``words``; keeps the
    highest VmHWM [MiB] seen (``peak_mb``, None if none was seen or /proc is missing)."""

    def __init__(self, *words: str, period_s: float = 0.05) -> None:
        self.words, self.period_s = words, period_s
        self.peak_mb: float | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="peak-rss", daemon=True)

    def __enter__(self) -> "PeakRss":
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

    def _children(self) -> list[int]:
        pids = []
        for children in Path("/proc/self/task").glob("*/children"):
            try:
                pids += [int(p) for p in children.read_text().split()]
            except OSError:
                continue
        return pids

    def _run(self) -> None:
        while not self._stop.is_set():
            for pid in self._children():
                try:
                    cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
                    if not all(w.encode() in cmdline for w in self.words):
                        continue
                    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
                        if line.startswith("VmHWM:"):
                            mb = int(line.split()[1]) / 1024.0  # kB -> MiB
                            self.peak_mb = mb if self.peak_mb is None else max(self.peak_mb, mb)
                except (OSError, ValueError):
                    continue  # the process just ended
            self._stop.wait(self.period_s)


def failsafe_texts(tlog: Path) -> list[str]:
    """STATUSTEXTs in a flight's tlog that announce a failsafe ("Failsafe activated...")."""
    from mission.mavlink.env import mavutil

    if not tlog.exists():
        return []
    conn = mavutil.mavlink_connection(str(tlog))
    texts = []
    try:
        while True:
            msg = conn.recv_match(type="STATUSTEXT")
            if msg is None:
                break
            if "failsafe activated" in str(msg.text).lower():
                texts.append(str(msg.text).rstrip())
    finally:
        conn.close()
    return texts


def demo_run(speed: float, timeout_s: float | None = None, config: str = str(DEFAULT_CONFIG)) -> dict:
    """One ``marsupial demo`` (one pair) at ``speed``; the figures of the module docstring."""
    timeout_s = timeout_s if timeout_s is not None else max(60.0, 120.0 / speed + 30.0)
    with tempfile.TemporaryDirectory(prefix="bench-demo-") as tmp, PeakRss("mission.cli", "run") as rss:
        t0 = time.monotonic()
        code, summaries = run_demo(config, speed, 1, Path(tmp), None, timeout_s, quiet=True, progress=False)
        wall_s = time.monotonic() - t0
        summary = summaries[0]
        log_dir = Path(tmp) / "pair0"
        failsafes = failsafe_texts(log_dir / "flight.tlog")
        simulated_s = None
        if (log_dir / "record.csv").exists():
            rec = read_record(log_dir)
            if len(rec.t) > 1:
                simulated_s = float(rec.t[-1] - rec.t[0])
    p = [bool(summary.get(k)) for k in ("p1", "p2", "p3")]
    aborted = summary.get("phase") != "DONE"
    return {
        "speed": speed, "wall_s": wall_s, "simulated_s": simulated_s,
        "realtime_factor": None if simulated_s is None else simulated_s / wall_s,
        "p1": p[0], "p2": p[1], "p3": p[2], "exit_code": summary.get("mission_exit_code"), "demo_exit_code": code,
        "phase": summary.get("phase"), "reason": summary.get("reason"),
        "ticks": summary.get("ticks"), "loop_overruns": summary.get("loop_overruns"),
        "max_offset_before_separation_m": summary.get("max_offset_before_separation_m"),
        "failsafe_texts": failsafes, "offboard_loss": bool(failsafes) or aborted,
        "ok": all(p) and not failsafes and not aborted and code == 0,
        "mission_peak_rss_mb": rss.peak_mb,
    }
