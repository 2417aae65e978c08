"""Shared fixtures: free loopback ports, config paths."""
from __future__ import annotations

import socket
from pathlib import Path

import pytest

import mission.mavlink_env  # noqa: F401  (sets MAVLINK20 before anything imports pymavlink's mavutil)

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A port the OS just handed out on 127.0.0.1 (for endpoints that must be named up front)."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def configs_dir() -> Path:
    return CONFIGS
