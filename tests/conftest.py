"""Shared fixtures: free loopback ports, config paths."""
from __future__ import annotations

import os
from collections.abc import Mapping, MutableMapping
from pathlib import Path

import pytest

import mission.mavlink.env  # noqa: F401  (sets MAVLINK20 before anything imports pymavlink's mavutil)
from mission.lifetime import supervise_children
from sim.net import LANE_ENV, free_port  # noqa: F401  (re-exported for the tests)

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"
#: The least a configuration file for `marsupial run` / `marsupial carrier` states
#: (mission.config.required): a target and both robots' speed and acceleration limits.
FLIGHT_TOML = ("[scenario]\ntarget = [20.0, 15.0, -4.0]\n[safety]\npassenger_max_speed_m_s = 3.0\n"
               "passenger_max_accel_m_s2 = 2.0\ncarrier_max_speed_m_s = 2.0\ncarrier_max_accel_m_s2 = 1.0\n")

supervise_children()  # every command a test starts ends with the test run, even one killed outright


def xdist_port_lane(env: Mapping[str, str]) -> str | None:
    """The port lane ``"i/n"`` of a pytest-xdist worker (``gw<i>`` of n), None outside xdist."""
    worker, count = env.get("PYTEST_XDIST_WORKER", ""), env.get("PYTEST_XDIST_WORKER_COUNT", "")
    if not (worker.startswith("gw") and worker[2:].isdigit() and count.isdigit()):
        return None
    return f"{int(worker[2:])}/{int(count)}"


def keep_bytecode(env: MutableMapping[str, str], cache: Path) -> bool:
    """With ``PYTHONDONTWRITEBYTECODE`` set (no ``.pyc`` beside the sources) every command a test
    starts (``python -m mission.cli ...``: hundreds in a run) would compile the whole package from
    source again; keep its bytecode out of the source tree instead, in ``cache``
    (``PYTHONPYCACHEPREFIX``). Nothing changes when bytecode is written anyway or a prefix is
    already chosen. True when ``env`` was changed."""
    if not env.get("PYTHONDONTWRITEBYTECODE") or env.get("PYTHONPYCACHEPREFIX"):
        return False
    del env["PYTHONDONTWRITEBYTECODE"]
    env["PYTHONPYCACHEPREFIX"] = str(cache)
    return True


def user_cache() -> Path:
    """This user's cache folder for the commands' bytecode (private: ``~/.cache``, not ``/tmp``)."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "marsupial" / "pycache"


keep_bytecode(os.environ, user_cache())

_lane = xdist_port_lane(os.environ)
if _lane is not None:  # parallel workers (and the commands they start) never pick the same port
    os.environ[LANE_ENV] = _lane


@pytest.fixture
def configs_dir() -> Path:
    return CONFIGS
