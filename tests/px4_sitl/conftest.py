"""Real PX4 SITL flights: skipped, with the reason, unless ``MARSUPIAL_PX4_SITL`` names a PX4
SITL build (a folder with ``bin/px4`` and ``etc/``) and we may make network namespaces.

The flights fly with at most :data:`PX4S_AT_ONCE` PX4 instances running together: two quadrotor
flights at once, the rover pair (two PX4s of its own) alone. Each flight is real time (about
40-80 s of wall time, the rover pair's whole cycle about 120 s) but light (about a quarter of a
core per PX4 with our controller and carrier), and each has a network namespace and a private
``/tmp`` of its own, so nothing is shared but the CPU. Not more: with six PX4s and eight of our processes starting together on two
cores SIH's sensors timed out in one run of three (``MAG #0 failed: TIMEOUT``, no baro) and PX4
failed over to ALTCTL; with three (the rover pair beside a quadrotor flight) a CI run on a quiet
machine lost baro and compass data just after take-off and PX4 fell back to ALTCTL; and once with
two quadrotor flights that started together ("No valid data from Baro 0", "invalid setpoints",
ALTCTL 4 s into OFFBOARD), so jobs start :data:`STAGGER_S` apart.

A flight that measures how closely PX4 holds a point (``alone=True``: the riding offset, the
hover speed) flies with no other PX4 beside it. Two such flights at once on two cores, neither
stalled, gave riding offsets of 0.164-0.289 m (3 of 8 over 0.24 m) and hover speeds up to
0.41 m/s; one at a time 0.16-0.23 m and 0.16-0.27 m/s (docs/px4-hold.md, "Two at once"). The
other flight's CPU is the test rig's, not the vehicle's: a real companion computer does not run a
second simulated autopilot.

A flight is a *job* (a function of its folder and the PX4 build that returns what the test
checks), registered with :func:`px4_job` and named by the test with
``@pytest.mark.px4_job(NAME)``; the session fixture ``px4_jobs`` starts every selected test's job
when the first of them asks, and each test waits for its own (an assertion error in a job fails
that job's test)."""
from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest

from sim.sitl.px4 import unavailable_reason
from tests.conftest import CONFIGS

# What holding a point on PX4 must give (docs/px4-hold.md). The targets are riding 0.20 m,
# last metre 4 s, hover 0.2 m/s. These bounds are where PX4's own estimate noise puts 16 flights
# of configs/px4_sitl.toml on this machine (`bench.px4_flights -n 8 --parallel 2`, on ad3cc8e and
# on its successor, 4 December 2026): riding 0.161-0.272 m (9 of 16 over the 0.20 target, 4 over
# the 0.25 this test asserted, which failed CI once), hover 0.169-0.311 m/s, last metre 1.6-2.24 s.
# The targets' misses are the bench's to report; a bound a flight of PX4 breaks at random proves nothing.
# The rover pair's flight holds its target to the same bounds: its own 0.3 m/s failed CI at 0.302 (a649221).
RIDING_OFFSET_M = 0.35  # the largest distance from the dock point while riding (P1's tolerance is 0.5)
LAST_METRE_S = 5.0  # first within 1 m of the target -> ARRIVED
HOVER_SPEED_M_S = 0.4  # mean horizontal speed while the reference sits on the target
ARRIVAL_RADIUS_M = 0.5  # once within it, never farther from the target again

Job = Callable[[Path, Path], Any]
JOBS: dict[str, tuple[Job, int]] = {}  # name -> (flight, PX4 slots it takes)


def px4_job(name: str, px4s: int = 1, alone: bool = False) -> Callable[[Job], Job]:
    """Register ``fn(directory, build)`` as the flight named ``name``; it runs ``px4s`` PX4
    instances, and with ``alone`` no other job flies beside it (it takes every slot)."""
    def register(fn: Job) -> Job:
        assert name not in JOBS, f"two PX4 jobs named {name}"
        assert 1 <= px4s <= PX4S_AT_ONCE, px4s
        JOBS[name] = (fn, PX4S_AT_ONCE if alone else px4s)
        return fn
    return register


_SELECTED = pytest.StashKey[list[str]]()
PX4S_AT_ONCE = 2  # PX4 instances running together (see above)
STAGGER_S = 10.0  # [s] wall time between two jobs' starts (their PX4s' boot and take-off)


@pytest.hookimpl(trylast=True)  # after -k / -m deselected theirs: fly only what will be checked
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    config.stash[_SELECTED] = list(dict.fromkeys(m.args[0] for item in items for m in item.iter_markers("px4_job")))


@pytest.fixture(scope="session")
def px4_jobs(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Future]]:
    """Every selected PX4 job, started in the order the tests come, with at most
    :data:`PX4S_AT_ONCE` PX4 instances running; leaving waits for all of them."""
    why = unavailable_reason()
    if why:
        pytest.skip(why)
    from sim.sitl.px4 import build_dir

    build = build_dir()
    names = request.config.stash.get(_SELECTED, [])
    slots = threading.Condition()
    free = [PX4S_AT_ONCE]
    turn = [0]  # the jobs start in the tests' order (their index in ``names``)
    last_start = [-math.inf]

    def fly(index: int, job: Job, px4s: int, directory: Path) -> Any:
        with slots:  # a job waits for its turn and until all the PX4s it needs are free
            # In turn, not whoever wakes first: a one-PX4 job released and took a slot again on the
            # same pool thread before a job that flies alone woke, so the lone job starved until
            # every later job had flown, and its test ran out of time (240 s) waiting.
            slots.wait_for(lambda: turn[0] == index and free[0] >= px4s)
            free[0] -= px4s
            turn[0] += 1
            slots.notify_all()
            # and starts its PX4 at least STAGGER_S after the last one started: two PX4s booting
            # together starved SIH's simulated baro, and PX4 failed over to ALTCTL after take-off
            wait_s = last_start[0] + STAGGER_S - time.monotonic()
            last_start[0] = time.monotonic() + max(wait_s, 0.0)
        if wait_s > 0:
            time.sleep(wait_s)
        try:
            return job(directory, build)
        finally:
            with slots:
                free[0] += px4s
                slots.notify_all()

    with ThreadPoolExecutor(max_workers=PX4S_AT_ONCE, thread_name_prefix="px4-job") as pool:
        yield {name: pool.submit(fly, index, *JOBS[name], tmp_path_factory.mktemp(f"px4-{name}"))
               for index, name in enumerate(names)}


# PX4 SITL's battery simulator empties in 60 s (and stops at 50 %): a recall would bring the
# passenger home from the way out (docs/recovery.md, "The battery"). A 10-minute battery.
TEN_MINUTE_BATTERY = {"SIM_BAT_DRAIN": 600.0}
# The holdoff's settling, relaxed for PX4 SITL's tracking (its SIH estimate wanders 0.1-0.3 m):
# the flights that use it are about failsafes and stalls, not about docking precision.
RELAXED_SETTLING = """
[recovery]
settle_radius_m = 0.6
settle_speed_m_s = 0.5
settle_dwell_s = 0.5
"""


def px4_return_config(directory: Path) -> Path:
    """configs/px4_sitl.toml coming home (``final_action = "return"``), the holdoff's settling
    relaxed (:data:`RELAXED_SETTLING`), written to ``directory``."""
    text = (CONFIGS / "px4_sitl.toml").read_text()
    assert 'final_action = "hold"' in text
    path = directory / "px4_sitl_return.toml"
    path.write_text(text.replace('final_action = "hold"', 'final_action = "return"\nat_target_s = 0.0') + RELAXED_SETTLING)
    return path
