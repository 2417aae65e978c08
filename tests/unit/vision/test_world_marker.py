"""The simulated world's marker (sim/camera/world_sensor.py) and where vision's file reading lives."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np

from mission.config.schema import load_config
from sim.camera.world_sensor import WorldMarker
from tests.conftest import CONFIGS, ROOT


def test_the_marker_lies_on_the_deck_at_the_dock_point():
    """The marker is where the vehicle sits when docked: the carrier's reference point plus
    ``mission.dock_offset_ned_m`` (the old code put it at the carrier's reference point, 1.5 m
    under the dock point of configs/relnav.toml)."""
    cfg = load_config(CONFIGS / "relnav.toml")
    carrier_at = np.array([3.0, -2.0, 0.0])
    world = SimpleNamespace(
        cfg=cfg, vehicle=SimpleNamespace(kin=SimpleNamespace(yaw_rad=0.0), true_position=np.array([3.0, -2.0, -3.0])),
        carrier=SimpleNamespace(true_at=lambda t: (carrier_at.copy(), np.zeros(3)), yaw_rad=0.0),
        scenario=SimpleNamespace(seed=0))
    poses = WorldMarker(world, lambda poses, t: None).poses(1.0)  # type: ignore[arg-type]
    assert np.allclose(poses.deck_ned_m, carrier_at + np.asarray(cfg.mission.dock_offset_ned_m))


def test_the_pure_vision_modules_read_no_file():
    """mission/vision is pure core but its I/O adapter (capture.py: the camera and its calibration
    file): no module of it opens or reads a file (the calibration file was read in camera.py)."""
    readers = ("read_text(", "read_bytes(", "open(", "FileStorage(", "VideoCapture(", "imread(")
    found = [f"{p.name}: {r}" for p in sorted((ROOT / "mission" / "vision").glob("*.py")) if p.name != "capture.py"
             for r in readers if r in Path(p).read_text()]
    assert found == []
