"""Shared fixtures: free loopback ports, config paths."""
from __future__ import annotations

from pathlib import Path

import pytest

import mission.mavlink_env  # noqa: F401  (sets MAVLINK20 before anything imports pymavlink's mavutil)
from mission.lifetime import supervise_children
from sim.net import free_port  # noqa: F401  (re-exported for the tests)

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"

supervise_children()  # every command a test starts ends with the test run, even one killed outright


@pytest.fixture
def configs_dir() -> Path:
    return CONFIGS
