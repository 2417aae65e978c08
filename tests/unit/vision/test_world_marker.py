"""The simulated world's marker (sim/camera/world_sensor.py) and where vision's file reading lives."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from mission.config.schema import load_config
from sim.camera.world_sensor import WorldMarker
from tests.conftest import CONFIGS, ROOT


@pytest.mark.parametrize("configured", [True, False])
def test_the_marker_lies_where_the_configuration_puts_it(configured: bool):
    """The marker lies at the carrier's reference point plus ``vision.marker_offset_ned_m``
    (configs/relnav.toml: on the deck, 1.5 m under the hover ride's dock point, in the riding
    camera's view); unset, at the dock point, ``mission.dock_offset_ned_m``, where the vehicle
    sits when docked (a deck ride)."""
    cfg = load_config(CONFIGS / "relnav.toml")
    if not configured:
        cfg = cfg.model_copy(update={"vision": cfg.vision.model_copy(update={"marker_offset_ned_m": None})})
    carrier_at = np.array([3.0, -2.0, 0.0])
    world = SimpleNamespace(
        cfg=cfg, vehicle=SimpleNamespace(kin=SimpleNamespace(yaw_rad=0.0), true_position=np.array([3.0, -2.0, -3.0])),
        carrier=SimpleNamespace(true_at=lambda t: (carrier_at.copy(), np.zeros(3)), yaw_rad=0.0),
        scenario=SimpleNamespace(seed=0))
    poses = WorldMarker(world, lambda poses, t: None).poses(1.0)  # type: ignore[arg-type]
    expected = cfg.vision.marker_offset_ned_m if configured else cfg.mission.dock_offset_ned_m
    assert np.allclose(poses.deck_ned_m, carrier_at + np.asarray(expected))
    assert configured == (poses.deck_ned_m[2] - carrier_at[2] == 0.0)  # the deck, not 1.5 m over it


def test_the_pure_vision_modules_read_no_file():
    """mission/vision is pure core but its I/O adapter (capture.py: the camera and its calibration
    file): no module of it opens or reads a file (the calibration file was read in camera.py)."""
    readers = ("read_text(", "read_bytes(", "open(", "FileStorage(", "VideoCapture(", "imread(")
    found = [f"{p.name}: {r}" for p in sorted((ROOT / "mission" / "vision").glob("*.py")) if p.name != "capture.py"
             for r in readers if r in Path(p).read_text()]
    assert found == []
