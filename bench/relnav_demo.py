"""``configs/relnav.toml`` (or another ``[relnav]`` configuration) flown by the lockstep demo (three
processes: the mock vehicle, ``marsupial carrier``, ``marsupial run``), held against the world's
truth: per leg whether it docked and at which approach, the true contact error and riding offset
(the mock's true position against the carrier's true dock point, :func:`sim.robots.truth.demo_truth`)
beside the estimate's, P1-P3 and the largest command jump at a phase switch.

    PYTHONPATH=. python -m bench.relnav_demo configs/relnav.toml [--seeds 0 1 2 3] [--log-root DIR]

A seed ``k`` draws the carrier's and the passenger's GNSS errors anew as ``bench.relnav_flight``
does (``world.carrier_gnss.seed`` and ``world.passenger_gnss.seed`` plus ``1000 k``: a copy of the
file with those two lines changed), and the vehicle's estimate errors and the camera's sensor from
``demo --seed k``; seed 0 is the configuration as written.
"""
from __future__ import annotations

import argparse
import json
import re
import resource
import tempfile
import time
from pathlib import Path
from typing import Any

from mission.config.schema import load_config
from sim.demo import run_demo


def seeded_file(path: Path, seed: int, folder: Path) -> Path:
    """``path`` with its ``[world.carrier_gnss]`` and ``[world.passenger_gnss]`` seeds plus ``1000 seed``."""
    if seed == 0:
        return path
    w = load_config(path).world
    moved = {"world.carrier_gnss": w.carrier_gnss.seed + 1000 * seed,
             "world.passenger_gnss": w.passenger_gnss.seed + 1000 * seed}
    lines, section = [], ""
    for line in path.read_text().splitlines():
        head = re.match(r"\s*\[([^\]]+)\]", line)
        if head:
            section = head.group(1).strip()
        if section in moved and re.match(r"\s*seed\s*=", line):
            line = f"seed = {moved[section]}"
        lines.append(line)
    out = folder / f"{path.stem}-seed{seed}.toml"
    out.write_text("\n".join(lines) + "\n")
    got = load_config(out).world
    assert (got.carrier_gnss.seed, got.passenger_gnss.seed) == tuple(moved.values()), "the seeds were not moved"
    return out


def figures(s: dict) -> dict[str, Any]:
    """One flight's figures from the demo's summary of its pair (legs with the truth merged in)."""
    legs = []
    for leg in s.get("legs") or []:
        c = leg.get("contact") or {}
        legs.append({"outcome": leg.get("outcome"), "recovery": leg.get("recovery_outcome"),
                     "attempts": c.get("attempts"), "estimate_contact_m": c.get("horizontal_error_m"),
                     **{k: v for k, v in leg.items() if k.startswith("true_")},
                     "jump_m_s": leg.get("max_phase_switch_jump_m_s"), "p": [leg.get("p1"), leg.get("p2"), leg.get("p3")]})
    return {"phase": s.get("phase"), "reason": s.get("reason"), "docked_again": s.get("docked_again"),
            "p1": s.get("p1"), "p2": s.get("p2"), "p3": s.get("p3"),
            "max_phase_switch_jump_m_s": s.get("max_phase_switch_jump_m_s"), "deck_crash": s.get("deck_crash"),
            "legs": legs}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("config", type=Path)
    ap.add_argument("--seeds", type=int, nargs="*", default=[0])
    ap.add_argument("--log-root", type=Path, default=None)
    ap.add_argument("--timeout", type=float, default=1500.0, help="wall-clock limit of one flight [s]")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="relnav-demo-") as tmp:
        root = args.log_root or Path(tmp)
        for seed in args.seeds:
            config = seeded_file(args.config, seed, Path(tmp))
            t0, cpu0 = time.monotonic(), resource.getrusage(resource.RUSAGE_CHILDREN)
            code, summaries = run_demo(str(config), 1.0, 1, root / f"seed{seed}", None, args.timeout, progress=False,
                                       seed=seed)
            cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            print(json.dumps({"seed": seed, "exit_code": code, "wall_s": round(time.monotonic() - t0, 1),
                              "children_cpu_s": round(cpu1.ru_utime + cpu1.ru_stime - cpu0.ru_utime - cpu0.ru_stime, 1),
                              **figures(summaries[0])}), flush=True)


if __name__ == "__main__":
    main()
