"""The PX4 flights' processes run the mission code of the tree the flight is started from."""
from __future__ import annotations

from pathlib import Path

import mission
from sim.sitl import px4


def test_the_flights_processes_run_this_trees_mission_code() -> None:
    # PYTHONPATH and the working directory of `marsupial run` / `marsupial carrier` under a
    # Px4Flight: the repository holding sim/sitl/px4.py, where `-m mission.cli` finds this tree's package
    root = px4.REPO_ROOT
    assert (root / "mission" / "cli").is_dir() and (root / "sim" / "sitl" / "px4.py").is_file()
    assert root == Path(px4.__file__).resolve().parents[2]
    assert Path(mission.__file__).resolve().parent == root / "mission"  # the tests' own tree
