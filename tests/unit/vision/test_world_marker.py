"""The simulated world's marker (sim/camera/world_sensor.py) and where vision's file reading lives."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from mission.config.schema import load_config
from mission.vision.frames import quaternion_matrix
from sim.camera.world_sensor import WorldMarker
from sim.vehicle.physics.multicopter import GRAVITY_M_S2, KinState
from tests.conftest import CONFIGS, ROOT


def _poses(cfg, kin: KinState, carrier_at: np.ndarray):
    """The world's poses at 1 s: the vehicle's state ``kin`` (its true position the state's), the
    carrier standing at ``carrier_at`` [m] NED, heading north."""
    world = SimpleNamespace(
        cfg=cfg, vehicle=SimpleNamespace(kin=kin, true_position=np.array([kin.n_m, kin.e_m, kin.d_m])),
        carrier=SimpleNamespace(true_at=lambda t: (carrier_at.copy(), np.zeros(3)), yaw_rad=0.0),
        scenario=SimpleNamespace(seed=0))
    return WorldMarker(world, lambda poses, t: None).poses(1.0)  # type: ignore[arg-type]


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
    poses = _poses(cfg, KinState(3.0, -2.0, -3.0), carrier_at)
    expected = cfg.vision.marker_offset_ned_m if configured else cfg.mission.dock_offset_ned_m
    assert np.allclose(poses.deck_ned_m, carrier_at + np.asarray(expected))
    assert configured == (poses.deck_ned_m[2] - carrier_at[2] == 0.0)  # the deck, not 1.5 m over it


@pytest.mark.parametrize("yaw_deg", [0.0, 90.0, -135.0])
def test_the_camera_tilts_away_from_where_the_vehicle_accelerates(yaw_deg: float):
    """The world's camera is fixed to a multicopter: accelerating at 2.8 m/s^2 to the north (as
    the PX4 SITL quadrotor did in a holdoff after a rover pulling away) tilts its thrust north, so
    a downward camera looks 16 deg to the south, whatever the vehicle's heading; in a hover it
    looks straight down. (A level camera kept the marker in view where PX4's lost it.)"""
    cfg = load_config(CONFIGS / "relnav.toml")
    yaw = np.radians(yaw_deg)

    def optical_axis(an_m_s2: float) -> np.ndarray:
        q = _poses(cfg, KinState(0.0, 0.0, -5.0, yaw_rad=float(yaw), an_m_s2=an_m_s2), np.zeros(3)).attitude_q_wxyz
        return quaternion_matrix(q) @ np.array([0.0, 0.0, 1.0])  # the body's down axis in NED

    assert np.allclose(optical_axis(0.0), [0.0, 0.0, 1.0])
    axis = optical_axis(2.8)
    # the mock's roll and pitch are each atan(a / g) of the acceleration's body axes (ZYX angles): a
    # heading across the acceleration turns the tilt's direction by up to 0.6 deg
    assert axis[0] < 0 and abs(axis[1]) < 0.01
    assert np.degrees(np.arctan2(-axis[0], axis[2])) == pytest.approx(np.degrees(np.arctan2(2.8, GRAVITY_M_S2)), abs=0.5)


def test_the_pure_vision_modules_read_no_file():
    """mission/vision is pure core but its I/O adapter (capture.py: the camera and its calibration
    file): no module of it opens or reads a file (the calibration file was read in camera.py)."""
    readers = ("read_text(", "read_bytes(", "open(", "FileStorage(", "VideoCapture(", "imread(")
    found = [f"{p.name}: {r}" for p in sorted((ROOT / "mission" / "vision").glob("*.py")) if p.name != "capture.py"
             for r in readers if r in Path(p).read_text()]
    assert found == []
