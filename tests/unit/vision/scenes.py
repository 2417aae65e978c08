"""Scenes for the vision tests: a vehicle above the deck at a height, tilted, looking at it."""
from __future__ import annotations

import numpy as np

from mission.vision.camera import CameraModel, Mount
from mission.vision.frames import euler_quaternion, quaternion_matrix
from sim.camera.render import Poses

CAMERA = CameraModel.from_fov(640, 480, 80.0, Mount.downward((0.05, 0.0, 0.08)))
DECK_NED_M = np.array([3.0, -2.0, 0.0])


def aimed(camera: CameraModel, height_m: float, roll_deg: float, pitch_deg: float, yaw_deg: float,
          offset_m=(0.0, 0.0), deck_yaw_rad: float = 0.3) -> Poses:
    """The camera ``height_m`` [m] above the deck, its optical axis through the deck centre moved
    by ``offset_m`` [m] (north, east), the vehicle at the Tait-Bryan angles [deg]."""
    q = euler_quaternion(*np.radians([roll_deg, pitch_deg, yaw_deg]))
    rotation_ned_body = quaternion_matrix(q)
    axis = rotation_ned_body @ camera.mount.rotation_body_cam[:, 2]
    camera_ned = DECK_NED_M - axis * height_m / axis[2] - np.array([*offset_m, 0.0])
    return Poses(camera_ned - rotation_ned_body @ camera.mount.offset_body_m, q, DECK_NED_M, deck_yaw_rad)


def random_attitudes(seed: int, count: int, max_tilt_deg: float):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        roll, pitch = rng.uniform(-max_tilt_deg, max_tilt_deg, 2)
        yield float(roll), float(pitch), float(rng.uniform(-180, 180))


def truth(poses: Poses) -> np.ndarray:
    """The deck centre from the vehicle [m] NED."""
    return np.asarray(poses.deck_ned_m) - np.asarray(poses.vehicle_ned_m)
