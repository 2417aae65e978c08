"""Where the suite's CPU goes: a pytest plugin that writes each test's CPU time [s].

``python -m pytest -p bench.pytest_cpu ...`` (with or without ``-n``): around each test's whole
run protocol (setup, call, teardown) it takes the difference of the process's own CPU (user +
system, ``RUSAGE_SELF``) and of its reaped children's (``RUSAGE_CHILDREN``: the commands a test
starts and waits for, with their own children), and appends one JSON line per test to
``$MARSUPIAL_CPU_LOG`` (default ``pytest-cpu.jsonl``; each xdist worker appends its own lines).
A module-scoped fixture's flight is charged to the first test that asks for it, as pytest's own
``--durations`` does. ``python -m bench.pytest_cpu FILE`` prints the total, the slowest tests and
each ``--dist loadscope`` unit's (a module, or a class), whose sum is the most one worker spends
on it (docs/testing.md, "The first part's wall time").
"""
from __future__ import annotations

import collections
import json
import os
import resource
import sys
import time
from collections.abc import Iterator
from typing import Any

import pytest

LOG_ENV = "MARSUPIAL_CPU_LOG"
HEAVY_S = 5.0  # a test of this much CPU [s] or more is a flight (docs/testing.md)


def _cpu() -> tuple[float, float]:
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    own0, kids0 = _cpu()
    wall0 = time.monotonic()
    yield
    own1, kids1 = _cpu()
    line = {"test": item.nodeid, "self_s": round(own1 - own0, 3), "children_s": round(kids1 - kids0, 3),
            "wall_s": round(time.monotonic() - wall0, 3), "worker": os.environ.get("PYTEST_XDIST_WORKER", "")}
    with open(os.environ.get(LOG_ENV, "pytest-cpu.jsonl"), "a") as f:
        f.write(json.dumps(line) + "\n")


def unit(nodeid: str) -> str:
    """The ``--dist loadscope`` unit of a test: its class if it has one, else its module."""
    parts = nodeid.split("::")
    return "::".join(parts[:2]) if len(parts) > 2 else parts[0]


def report(lines: list[dict[str, Any]], top: int = 10) -> str:
    cpu = {d["test"]: d["self_s"] + d["children_s"] for d in lines}
    wall = {d["test"]: d["wall_s"] for d in lines}
    units: collections.Counter[str] = collections.Counter()
    unit_wall: collections.Counter[str] = collections.Counter()
    for test, c in cpu.items():
        units[unit(test)] += c
        unit_wall[unit(test)] += wall[test]
    own, kids = sum(d["self_s"] for d in lines), sum(d["children_s"] for d in lines)
    out = [f"{len(lines)} tests: CPU {own + kids:.0f} s (the workers' own {own:.0f} s, their commands' {kids:.0f} s), "
           f"wall summed over the workers {sum(wall.values()):.0f} s"]
    heavy = [c for c in cpu.values() if c >= HEAVY_S]
    total, heavy_s = own + kids, sum(heavy)
    out += [f"the {len(heavy)} tests of {HEAVY_S:.0f} s of CPU or more (the flights) {heavy_s:.0f} s, "
            f"the other {len(cpu) - len(heavy)} {total - heavy_s:.0f} s; on two cores at least {total / 2:.0f} s of wall",
            "", f"the {top} most CPU [s] (wall [s]):"]
    out += [f"{c:8.1f} ({wall[t]:6.1f})  {t}" for t, c in sorted(cpu.items(), key=lambda kv: -kv[1])[:top]]
    out += ["", f"the {top} loadscope units of most CPU [s] (wall [s]):"]
    out += [f"{c:8.1f} ({unit_wall[u]:6.1f})  {u}" for u, c in units.most_common(top)]
    return "\n".join(out)


if __name__ == "__main__":
    path = sys.argv[1] if len(sys.argv) > 1 else "pytest-cpu.jsonl"
    with open(path) as f:
        print(report([json.loads(line) for line in f if line.strip()], int(sys.argv[2]) if len(sys.argv) > 2 else 10))
