"""Real PX4 SITL flights: skipped, with the reason, unless ``MARSUPIAL_PX4_SITL`` names a PX4
SITL build (a folder with ``bin/px4`` and ``etc/``) and we may make network namespaces.

The flights fly two at a time. Each is real time (about 40-70 s of wall time) but light (about a
quarter of a core: PX4 SIH, our controller and the carrier), and each has a network namespace and
a private ``/tmp`` of its own, so nothing is shared but the CPU. Not all at once: with the four
flights' six PX4s and eight of our processes starting together on two cores, SIH's sensors timed
out in one run of three (``MAG #0 failed: TIMEOUT``, no baro) and PX4 failed over to ALTCTL. A flight is a *job* (a function of
its folder and the PX4 build that returns what the test checks), registered with
:func:`px4_job` and named by the test with ``@pytest.mark.px4_job(NAME)``; the session fixture
``px4_jobs`` starts every selected test's job when the first of them asks, and each test waits
for its own (an assertion error in a job fails that job's test)."""
from __future__ import annotations

from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest

from sim.px4_sitl import unavailable_reason

Job = Callable[[Path, Path], Any]
JOBS: dict[str, Job] = {}


def px4_job(name: str) -> Callable[[Job], Job]:
    """Register ``fn(directory, build)`` as the flight named ``name``."""
    def register(fn: Job) -> Job:
        assert name not in JOBS, f"two PX4 jobs named {name}"
        JOBS[name] = fn
        return fn
    return register


_SELECTED = pytest.StashKey[list[str]]()
AT_ONCE = 2  # flights in the air together (see above)


@pytest.hookimpl(trylast=True)  # after -k / -m deselected theirs: fly only what will be checked
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    config.stash[_SELECTED] = list(dict.fromkeys(m.args[0] for item in items for m in item.iter_markers("px4_job")))


@pytest.fixture(scope="session")
def px4_jobs(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Future]]:
    """Every selected PX4 job, :data:`AT_ONCE` at a time in the order the tests come; leaving
    waits for all of them."""
    why = unavailable_reason()
    if why:
        pytest.skip(why)
    from sim.px4_sitl import build_dir

    build = build_dir()
    names = request.config.stash.get(_SELECTED, [])
    with ThreadPoolExecutor(max_workers=AT_ONCE, thread_name_prefix="px4-job") as pool:
        yield {name: pool.submit(JOBS[name], tmp_path_factory.mktemp(f"px4-{name}"), build) for name in names}
