"""``marsupial bench`` / ``python -m bench``: every benchmark in one table, plus JSON.

Sections (``--section NAME``, repeatable; all by default):

1. ``tick``   law + safety tick (:func:`bench.law_bench.tick_latency`), 0/1/8 obstacles.
   ``wire``   decoding one bus sample (:mod:`bench.wire_bench`): JSON carrier state and
              passenger status, CDR Odometry, a hostile JSON sample refused.
   ``vision`` one 640x480 frame (:mod:`bench.vision_cost`): render, the bare detector (the
              floor), detection + pose, a region of interest, one threshold pass (thread CPU).
2. ``e2e``    carrier sample published on Zenoh -> the setpoint computed from it arrives at the
              vehicle's socket, controller at 50 and 250 Hz, beside the transport floor (Zenoh-only
              and MAVLink-only pings) measured in the same run (:mod:`bench.e2e` tells how).
3. ``stream`` setpoint stream asked at 50, 250 and 1000 Hz: achieved rate, jitter p99, CPU share
              of the controller process (same controller runs as ``e2e``).
4. ``demo``   ``marsupial demo`` (three processes) at speed 1, 10, 20 and 50: wall time, P1-P3,
              offboard loss (:mod:`bench.demo_bench`); the highest speed that holds.
5. ``batch``  closed-loop batch simulation, scenario-steps/s, beside numba
              (:func:`bench.law_bench.batch_throughput`, :func:`bench.law_bench.numba_baseline`).
6. ``memory`` peak resident memory of the controller process (the demo's ``marsupial run`` and
              the ``e2e``/``stream`` controller runs).

Figures are wall-clock times on a shared machine: the table starts with the machine and its load
average, and a floor measured in the same run stands beside the end-to-end figures. Each target is printed next to its figure with ``pass`` or ``MISS``.
"""
from __future__ import annotations

import json
import os
import platform
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable

import click
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SECTIONS = ("tick", "wire", "vision", "e2e", "stream", "demo", "batch", "memory")
E2E_RATES_HZ = (50.0, 250.0)
STREAM_RATES_HZ = (50.0, 250.0, 1000.0)
DEMO_SPEEDS = (1.0, 10.0, 20.0, 50.0)
DEMO_REPEATS = 3  # runs per speed above 1 (a full run); the demo's margins are thin under load
CARRIER_RATE_HZ = 30.0  # the demo carrier's rate: the cadence of the samples and of the Zenoh ping


@dataclass
class Row:
    """One line of the table: a figure, its value, its target and whether it holds."""

    section: str
    figure: str
    value: str
    target: str = ""
    ok: bool | None = None


def machine() -> dict[str, Any]:
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import numpy

    return {"platform": platform.platform(), "cpu": cpu, "cpu_count": os.cpu_count(),
            "python": f"{platform.python_implementation()} {platform.python_version()}", "numpy": numpy.__version__,
            "load_average": [round(x, 2) for x in os.getloadavg()]}


def _ms(d: dict | None, key: str = "p50_ms") -> str:
    return "-" if d is None or d.get(key) is None else f"{d[key]:.3f}"


def _pair(d: dict) -> str:
    return f"{_ms(d)} / {_ms(d, 'p99_ms')}"


class Bench:
    """Runs the sections, shares the controller runs between ``e2e`` and ``stream``."""

    def __init__(self, quick: bool) -> None:
        self.quick = quick
        self.results: dict[str, Any] = {}
        self.rows: list[Row] = []
        self._runs: dict[float, Any] = {}

    # ------------------------------------------------------------------ helpers
    def controller_run(self, rate_hz: float) -> Any:
        from bench.e2e import run_controller

        if rate_hz not in self._runs:
            duration = 3.0 if self.quick else 10.0
            self._runs[rate_hz] = run_controller(rate_hz, duration, carrier_rate_hz=CARRIER_RATE_HZ)
        return self._runs[rate_hz]

    def row(self, section: str, figure: str, value: str, target: str = "", ok: bool | None = None) -> None:
        self.rows.append(Row(section, figure, value, target, ok))

    # ------------------------------------------------------------------ sections
    def tick(self) -> None:
        from bench.law_bench import tick_latency

        samples = 3000 if self.quick else 20000
        ticks = [tick_latency(n, samples) for n in (0, 1, 8)]
        self.results["tick"] = ticks
        for t in ticks:
            n = t["obstacles"]
            target, ok = ("p99 <= 50 us", t["p99_us"] <= 50.0) if n == 8 else ("", None)
            self.row("tick", f"{n} obstacles: p50 / p99 [us] (thread CPU)",
                     f"{t['p50_us']:.1f} / {t['p99_us']:.1f} ({t['cpu_p50_us']:.1f} / {t['cpu_p99_us']:.1f})", target, ok)

    def wire(self) -> None:
        from bench.wire_bench import decode_costs

        costs = decode_costs(2000 if self.quick else 20000)
        self.results["wire"] = costs
        for c in costs:
            self.row("wire", f"{c['message']}: p50 / p99 [us] (thread CPU)", f"{c['p50_us']:.1f} / {c['p99_us']:.1f}")

    def vision(self) -> None:
        from bench.vision_cost import TARGET_MS, run

        rows = run(50 if self.quick else 200)
        self.results["vision"] = rows
        for r in rows:
            target, ok = ((f"p50 <= {TARGET_MS:g} ms", r["cpu_p50_ms"] <= TARGET_MS) if r["figure"] == "detection + pose"
                          else ("", None))
            self.row("vision", f"{r['figure'].strip()}: p50 / p95 [ms] (thread CPU)",
                     f"{r['cpu_p50_ms']:.2f} / {r['cpu_p95_ms']:.2f}", target, ok)

    def e2e(self) -> None:
        from bench.floor import mavlink_ping, zenoh_ping

        n = 100 if self.quick else 300
        zen = zenoh_ping(n, 1.0 / CARRIER_RATE_HZ)
        zen_one = zenoh_ping(n, 1.0 / CARRIER_RATE_HZ, two_processes=False)
        out: dict[str, Any] = {"zenoh_ping": zen, "zenoh_ping_one_process": zen_one}
        self.row("e2e", f"floor: Zenoh ping, 2 procs, {CARRIER_RATE_HZ:g} Hz: p50 / p99 [ms]", _pair(zen))
        self.row("e2e", f"       Zenoh ping, 1 proc, {CARRIER_RATE_HZ:g} Hz: p50 / p99 [ms]", _pair(zen_one))
        for rate in E2E_RATES_HZ:
            mav = mavlink_ping(n, 1.0 / rate)
            run = self.controller_run(rate)
            floor = {k: zen[k] + mav[k] for k in ("p50_ms", "p99_ms")}
            seen, raw, legs = run.e2e_seen, run.e2e_raw, run.legs
            out[f"{rate:g}Hz"] = {"mavlink_ping": mav, "floor": floor, "raw": raw, "seen": seen, "legs": legs,
                                  "matched_samples": seen["n"], "mismatches": run.mismatches,
                                  "samples_unused": run.samples_unused, "notes": run.notes}
            at = f"{rate:g} Hz"
            self.row("e2e", f"floor: MAVLink ping, {at}: p50 / p99 [ms]", _pair(mav))
            self.row("e2e", f"floor: Zenoh + MAVLink at {at}: p50 / p99 [ms]", f"{floor['p50_ms']:.3f} / {floor['p99_ms']:.3f}")
            self.row("e2e", f"{at} raw, publish -> arrival: p50 / p99 [ms]", _pair(raw))
            on_target = rate == 50.0  # the targets are at 50 Hz; 250 Hz is shown beside them
            have = seen["p50_ms"] is not None
            self.row("e2e", f"{at} after seen (raw - wait), n={seen['n']}: p50 [ms]", _ms(seen),
                     "<= 0.5" if on_target else "", (have and seen["p50_ms"] <= 0.5) if on_target else None)
            self.row("e2e", f"{at} after seen (raw - wait): p99 [ms]", _ms(seen, "p99_ms"),
                     "<= 2" if on_target else "", (have and seen["p99_ms"] <= 2.0) if on_target else None)
            relative = have and seen["p50_ms"] <= 2 * floor["p50_ms"] and seen["p99_ms"] <= 2 * floor["p99_ms"]
            self.row("e2e", f"{at} after seen / floor: p50, p99 [x]",
                     "-" if not have else f"{seen['p50_ms'] / floor['p50_ms']:.2f}, {seen['p99_ms'] / floor['p99_ms']:.2f}",
                     "<= 2x floor" if on_target else "", relative if on_target else None)
            self.row("e2e", f"{at} p50 [ms]: Zenoh | wait | tick -> arrival",
                     f"{_ms(legs['zenoh'])} | {_ms(legs['wait'])} | {_ms(legs['tick_to_arrival'])}")
            self.row("e2e", f"{at} p50 [ms]: observe | step | send -> arrival",
                     f"{_ms(legs['observe'])} | {_ms(legs['step'])} | {_ms(legs['send_to_arrival'])}")
        from bench.law_bench import step_warm_cold

        sw = step_warm_cold(samples=50 if self.quick else 150)
        out["step_warm_cold"] = sw
        self.row("e2e", "phases.step (RIDING) back to back | after 20 ms idle: p50 [us]",
                 f"{sw['warm_p50_us']:.0f} | {sw['cold_p50_us']:.0f}")
        self.results["e2e"] = out

    def stream(self) -> None:
        out = {}
        for rate in STREAM_RATES_HZ:
            run = self.controller_run(rate)
            s = dict(run.stream, cpu_share=run.child["cpu_share"], overruns=run.child["overruns"])
            out[f"{rate:g}Hz"] = s
            achieved = s["achieved_hz"] or 0.0
            jitter = s["jitter_p99_ms"] if s["jitter_p99_ms"] is not None else float("inf")
            target, ok = ("", None)
            if rate == max(STREAM_RATES_HZ):
                target, ok = ">= 500 Hz, jitter p99 <= 2 ms", achieved >= 500.0 and jitter <= 2.0
            self.row("stream", f"{rate:g} Hz asked: achieved Hz, jitter p99 ms, CPU, overruns",
                     f"{achieved:.1f}, {jitter:.3f}, {100 * s['cpu_share']:.1f} %, {s['overruns']}", target, ok)
        self.results["stream"] = out

    def demo(self) -> None:
        """Each speed flown ``repeats`` times (once at speed 1): a speed holds when every run held."""
        from bench.demo_bench import demo_run

        speeds = DEMO_SPEEDS[1:] if self.quick else DEMO_SPEEDS
        repeats = 1 if self.quick else DEMO_REPEATS
        runs = [demo_run(s) for s in speeds for _ in range(1 if s == 1.0 else repeats)]
        self.results["demo"] = runs
        holds: dict[float, bool] = {}
        for speed in speeds:
            rs = [r for r in runs if r["speed"] == speed]
            holds[speed] = all(r["ok"] for r in rs)
            p = "/".join(str(sum(r[f"p{i}"] for r in rs)) for i in (1, 2, 3))
            losses = sum(r["offboard_loss"] for r in rs)
            offset = max(r["max_offset_before_separation_m"] or float("nan") for r in rs)
            wall = float(np.median([r["wall_s"] for r in rs]))
            factor = float(np.median([r["realtime_factor"] or 0.0 for r in rs]))
            self.row("demo", f"speed {speed:g} x{len(rs)}: wall s (sim/wall), P1/P2/P3, losses, offset m, overruns",
                     f"{wall:.1f} ({factor:.1f}x), {p}, {losses}, {offset:.2f}, "
                     f"{'/'.join(str(r['loop_overruns']) for r in rs)}", "", holds[speed])
        holding = [s for s in speeds if holds[s]]
        best = max(holding) if holding else None
        lower_failed = [s for s in speeds if not holds[s] and best is not None and s < best]
        note = f" (but {', '.join(f'{s:g}' for s in lower_failed)} failed)" if lower_failed else ""
        self.results["demo_highest_speed"] = best
        self.row("demo", "highest speed: P1-P3, no offboard loss, every run",
                 f"{best:g}{note}" if best else "none", ">= 20", best is not None and best >= 20 and not lower_failed)

    def batch(self) -> None:
        from bench.law_bench import batch_throughput, numba_baseline

        sizes = [(1, 500), (100, 500), (10000, 50)] if self.quick else [(1, 2000), (100, 2000), (10000, 300)]
        out = []
        for scenarios, steps in sizes:
            r = batch_throughput(scenarios, steps)
            base = numba_baseline(scenarios, steps)
            r["numba_scenario_steps_per_s"] = None if base is None else base["scenario_steps_per_s"]
            out.append(r)
            nb = r["numba_scenario_steps_per_s"]
            ratio = None if not nb else r["scenario_steps_per_s"] / nb
            target, ok = ("", None)
            if scenarios == max(s for s, _ in sizes):
                target = ">= 1e7 /s and >= 1/3 numba"
                ok = r["scenario_steps_per_s"] >= 1e7 and ratio is not None and ratio >= 1 / 3
            self.row("batch", f"{scenarios} scenarios: numpy | numba [steps/s], ratio",
                     f"{r['scenario_steps_per_s']:.3g} | {'-' if not nb else f'{nb:.3g}'}, "
                     f"{'-' if ratio is None else f'{ratio:.2f}'}", target, ok)
        self.results["batch"] = out

    def memory(self) -> None:
        if "demo" not in self.results and not self._runs:
            from bench.demo_bench import demo_run

            self.results["demo_for_memory"] = [demo_run(10.0)]
        out = {}
        demos = self.results.get("demo", []) + self.results.get("demo_for_memory", [])
        for speed in sorted({r["speed"] for r in demos}):
            peaks = [r["mission_peak_rss_mb"] for r in demos if r["speed"] == speed and r["mission_peak_rss_mb"]]
            peak = max(peaks) if peaks else None
            out[f"demo_speed_{speed:g}"] = peak
            self.row("memory", f"`marsupial run`, demo speed {speed:g}: peak RSS [MiB]",
                     "-" if peak is None else f"{peak:.1f}")
        for rate, run in sorted(self._runs.items()):
            out[f"controller_{rate:g}Hz"] = run.child["peak_rss_mb"]
            self.row("memory", f"controller at {rate:g} Hz, e2e run: peak RSS [MiB]",
                     f"{run.child['peak_rss_mb']:.1f}")
        self.results["memory_mb"] = out

    def run(self, sections: tuple[str, ...]) -> None:
        steps: dict[str, Callable[[], None]] = {name: getattr(self, name) for name in SECTIONS}
        for name in SECTIONS:  # the table's order, whatever the order asked
            if name in sections:
                t0 = time.monotonic()
                click.echo(f"running {name} ...", err=True)
                steps[name]()
                self.results.setdefault("section_wall_s", {})[name] = round(time.monotonic() - t0, 1)
        self.results["controller_runs"] = {f"{k:g}Hz": asdict(v) for k, v in self._runs.items()}


def format_table(info: dict[str, Any], rows: list[Row]) -> str:
    head = [f"machine: {info['platform']}, {info['cpu']}, {info['cpu_count']} CPUs, {info['python']}, "
            f"numpy {info['numpy']}",
            f"load average: {info['load_average']} at start, {info.get('load_average_end')} at end"]
    w_sec = max([len("section")] + [len(r.section) for r in rows])
    w_fig = max([len("figure")] + [len(r.figure) for r in rows])
    w_val = max([len("value")] + [len(r.value) for r in rows])
    w_tgt = max([len("target")] + [len(r.target) for r in rows])
    header = f"{'section':<{w_sec}}  {'figure':<{w_fig}}  {'value':<{w_val}}  {'target':<{w_tgt}}  result"
    lines = head + ["", header, "-" * len(header)]
    for r in rows:
        verdict = "" if r.ok is None else ("pass" if r.ok else "MISS")
        lines.append(f"{r.section:<{w_sec}}  {r.figure:<{w_fig}}  {r.value:<{w_val}}  {r.target:<{w_tgt}}  {verdict}")
    return "\n".join(lines)


@click.command("bench")
@click.option("--quick", is_flag=True, help="Fewer samples, shorter runs, no speed-1 demo (well under a minute "
              "of measuring, plus process start-ups).")
@click.option("--section", "sections", multiple=True, type=click.Choice(SECTIONS),
              help="Run only this section (repeatable). Default: all.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=str(Path("out") / "bench.json"),
              show_default=True, help="Where to write every figure as JSON.")
def bench(quick: bool, sections: tuple[str, ...], json_path: str) -> int:
    """Benchmarks of the controller against its floor and its targets.

    Prints one table (machine, figure, value, target, pass/MISS) and writes the raw figures as
    JSON. Sections: tick (law + safety), e2e (Zenoh sample -> MAVLink setpoint, beside the
    transport floor), stream (setpoint rate, jitter, CPU), demo (three processes at speed 1-50),
    batch (closed-loop simulation vs numba), memory (controller peak RSS). Uses free loopback
    ports only; run it on a quiet machine and repeat a noisy section with --section.
    """
    info = machine()
    b = Bench(quick)
    b.run(sections or SECTIONS)
    info["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    click.echo(format_table(info, b.rows))
    out = Path(json_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"machine": info, "quick": quick, "rows": [asdict(r) for r in b.rows], **b.results},
                              indent=2, default=str))
    click.echo(f"JSON: {out}")
    return 0


if __name__ == "__main__":
    bench()
