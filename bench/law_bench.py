"""Law + safety tick latency and batch-simulation throughput (prints a table, writes JSON).

    python -m bench.law_bench [--json out/bench_law.json] [--quick]

Tick: one realtime passenger tick (``mission.core.tick.passenger_tick``: law + CBF-QP filter + limits)
for one vector, with 0, 1 and 8 obstacles, p50/p99 in microseconds of wall-clock time and, beside
it, of the thread's CPU time (which leaves out the time the scheduler gave to other processes: on
a shared, loaded machine the wall-clock p99 is mostly that). Batch: the closed loop
(``sim.batch.closed_loop.simulate``) in scenario-steps per second for 1, 100 and 10 000 scenarios,
beside a compiled baseline of the same integrator (numba, if installed) measured in the same run.
"""
from __future__ import annotations

import json
import platform
import time
from pathlib import Path

import click
import numpy as np

from mission.config.schema import load_config
from mission.core.law import LawParams
from mission.core.safety import Obstacles, SafetyConfig
from mission.core.tick import TickModel, passenger_tick
from mission.model import model_from_config
from sim.batch.closed_loop import random_scenarios, simulate

ROOT = Path(__file__).resolve().parents[1]


def tick_latency(n_obstacles: int, samples: int = 20000) -> dict:
    rng = np.random.default_rng(0)
    centers = [(list(rng.uniform(-30, 30, 2)) + [-3.0], 1.0) for _ in range(n_obstacles)]
    if n_obstacles:
        centers[0] = ([3.0, 0.3, -1.5], 1.0)  # one obstacle right ahead: the filter works every tick
    model = TickModel(law=LawParams(), target=np.array([30.0, 10.0, -5.0]), obstacles=Obstacles.of(centers, 3),
                      passenger_safety=SafetyConfig(max_speed_m_s=3.0, max_accel_m_s2=2.0, z_max_m=-0.5),
                      carrier_safety=SafetyConfig(), planar_carrier=False)
    anchor = np.array([0.0, 0.0, -1.5])
    e_pc = np.array([0.5, 0.0, 0.0])
    u_prev = np.array([1.0, 0.0, 0.0])
    v_anchor = np.zeros(3)
    for _ in range(200):  # warm-up: first-use caches (obstacle keep-out radii, bound rows)
        passenger_tick(anchor, v_anchor, e_pc, True, model, u_prev, 0.02)
    times = np.empty(samples)
    cpu = np.empty(samples)
    for i in range(samples):
        c0 = time.thread_time_ns()
        t0 = time.perf_counter_ns()
        passenger_tick(anchor, v_anchor, e_pc, True, model, u_prev, 0.02)
        t1 = time.perf_counter_ns()
        cpu[i] = time.thread_time_ns() - c0
        times[i] = t1 - t0
    def pct(a: np.ndarray, q: float) -> float:
        return float(np.percentile(a, q) / 1e3)  # [ns] -> [us]

    return {"obstacles": n_obstacles, "p50_us": pct(times, 50), "p99_us": pct(times, 99),
            "cpu_p50_us": pct(cpu, 50), "cpu_p99_us": pct(cpu, 99)}


def batch_throughput(scenarios: int, steps: int) -> dict:
    cfg = load_config(ROOT / "configs" / "paper_3d.toml")
    starts, targets = random_scenarios(cfg, scenarios, seed=1)
    model = model_from_config(cfg, target=targets)
    t0 = time.perf_counter()
    simulate(model, starts, duration_s=steps * 1e-3, dt_s=1e-3, record_every=10**9)
    wall = time.perf_counter() - t0
    return {"scenarios": scenarios, "steps": steps, "wall_s": wall, "scenario_steps_per_s": scenarios * (steps + 1) / wall}


def numba_baseline(scenarios: int, steps: int) -> dict | None:
    """The same closed loop (paper law, planar carrier, separation latch, ZOH Euler) compiled."""
    try:
        import numba
    except ImportError:
        return None

    @numba.njit(cache=False, fastmath=False)
    def run(xc, tgt, steps, dt, kc, kp, b, c, d, ev):
        B = xc.shape[0]
        anchor = xc.copy()
        e = np.zeros_like(xc)
        sep = np.zeros(B, dtype=np.bool_)
        for _ in range(steps):
            for i in range(B):
                etc = tgt[i] - anchor[i]
                L = np.sqrt(etc[0] ** 2 + etc[1] ** 2 + etc[2] ** 2)
                uc = np.zeros(3)
                if not sep[i]:
                    uc[0], uc[1] = kc * etc[0], kc * etc[1]
                a = np.sqrt(e[i, 0] ** 2 + e[i, 1] ** 2 + e[i, 2] ** 2)
                P = kp * (a - L) * (a + d) * (a - L / b + c)
                if P >= 0:
                    rel = -P * e[i]
                else:
                    rel = P * (e[i] - etc)
                for k in range(3):
                    anchor[i, k] += uc[k] * dt
                    e[i, k] += rel[k] * dt
                etc2 = tgt[i] - anchor[i]
                if not sep[i] and np.sqrt(etc2[0] ** 2 + etc2[1] ** 2 + etc2[2] ** 2) <= ev:
                    sep[i] = True
        return e

    cfg = load_config(ROOT / "configs" / "paper_3d.toml")
    starts, targets = random_scenarios(cfg, scenarios, seed=1)
    p = cfg.law.params()
    run(starts[:2], targets[:2], 2, 1e-3, p.k_c, p.k_p, p.b, p.c, p.d, p.separation_distance_m - 1e-3)  # compile
    t0 = time.perf_counter()
    run(starts, targets, steps, 1e-3, p.k_c, p.k_p, p.b, p.c, p.d, p.separation_distance_m - 1e-3)
    wall = time.perf_counter() - t0
    return {"scenarios": scenarios, "steps": steps, "wall_s": wall, "scenario_steps_per_s": scenarios * steps / wall}


def step_warm_cold(gap_s: float = 0.02, samples: int = 150) -> dict:
    """One RIDING tick of :func:`mission.phases.step` (law + both filters) on the demo's model,
    back to back ("warm") and after sleeping ``gap_s`` before each call ("cold", as a 50 Hz loop
    is): p50/p99 [us]. The difference is what a mostly idle periodic loop pays on this machine
    (caches, branch predictors and the core's idle state), not what the code does."""
    from mission import phases
    from mission.config.schema import load_config
    from mission.model import mission_model
    from mission.phases import CarrierObs, MissionState, Observation, Phase, VehicleObs

    model = mission_model(load_config(ROOT / "configs" / "demo.toml"))
    dock = np.array([0.0, 0.0, -1.5])
    state = MissionState(phase=Phase.RIDING, x_ref=dock, e_ref=np.zeros(3), prev_dock=dock, u_ref=np.zeros(3),
                         u_cmd=np.zeros(3), start_s=0.0)
    obs = Observation(t_s=1.0, vehicle=VehicleObs(dock, np.zeros(3), True, "OFFBOARD", 0.1),
                      carrier=CarrierObs(np.zeros(3), np.zeros(3), 0.01))
    out = {}
    for name, gap, n in (("warm", 0.0, samples * 10), ("cold", gap_s, samples)):
        times = []
        for _ in range(n):
            if gap:
                time.sleep(gap)
            t0 = time.perf_counter_ns()
            phases.step(state, obs, model)
            times.append(time.perf_counter_ns() - t0)
        out[f"{name}_p50_us"] = float(np.percentile(times, 50) / 1e3)
        out[f"{name}_p99_us"] = float(np.percentile(times, 99) / 1e3)
    out["gap_s"] = gap_s
    return out


@click.command()
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=str(ROOT / "out" / "bench_law.json"),
              show_default=True, help="Where to write the figures (JSON).")
@click.option("--quick", is_flag=True, help="Fewer samples and steps.")
def main(json_path: str, quick: bool) -> dict:
    """Law + safety tick latency and batch throughput (see the module docstring)."""
    samples = 3000 if quick else 20000
    ticks = [tick_latency(n, samples) for n in (0, 1, 8)]
    sizes = [(1, 2000), (100, 2000), (10000, 300)] if not quick else [(1, 500), (100, 500), (10000, 50)]
    batches = []
    for scenarios, steps in sizes:
        row = batch_throughput(scenarios, steps)
        base = numba_baseline(scenarios, steps)
        row["numba_scenario_steps_per_s"] = None if base is None else base["scenario_steps_per_s"]
        batches.append(row)
    print(f"machine: {platform.machine()} {platform.processor() or ''} python {platform.python_version()}")
    print(f"{'tick (law + safety)':<24}{'p50 [us]':>10}{'p99 [us]':>10}{'cpu p50':>10}{'cpu p99':>10}")
    for r in ticks:
        print(f"{str(r['obstacles']) + ' obstacles':<24}{r['p50_us']:>10.1f}{r['p99_us']:>10.1f}"
              f"{r['cpu_p50_us']:>10.1f}{r['cpu_p99_us']:>10.1f}")
    print(f"{'batch':<12}{'steps':>8}{'numpy [steps/s]':>18}{'numba [steps/s]':>18}{'ratio':>8}")
    for r in batches:
        nb = r["numba_scenario_steps_per_s"]
        ratio = f"{r['scenario_steps_per_s'] / nb:>8.2f}" if nb else f"{'-':>8}"
        print(f"{r['scenarios']:<12}{r['steps']:>8}{r['scenario_steps_per_s']:>18.3g}{(nb or float('nan')):>18.3g}{ratio}")
    result = {"tick": ticks, "batch": batches}
    Path(json_path).parent.mkdir(parents=True, exist_ok=True)
    Path(json_path).write_text(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
