"""Rotations between the vision frames (camera, body FRD, NED, deck: see
:mod:`mission.vision.measurement`), as 3x3 matrices. ``rotation_a_b`` turns a vector in frame b's
axes into frame a's: ``v_a = rotation_a_b @ v_b``."""
from __future__ import annotations

import numpy as np

# The nominal downward camera in body FRD: the optical axis (camera z) down, the image's right
# (camera x) the body's right, the image's down (camera y) the body's back, so the image's top
# looks forward.
ROTATION_BODY_CAM_DOWN = np.array([[0.0, -1.0, 0.0],
                                   [1.0, 0.0, 0.0],
                                   [0.0, 0.0, 1.0]])

# A tag's own frame (OpenCV's aruco convention: x right and y up in the printed image, z out of the
# tag towards the viewer) in the deck frame, for a tag printed with its top towards the deck's
# forward and lying face up: tag x = deck y, tag y = deck x, tag z = -deck z (up).
ROTATION_DECK_TAG = np.array([[0.0, 1.0, 0.0],
                              [1.0, 0.0, 0.0],
                              [0.0, 0.0, -1.0]])


def quaternion_matrix(q_wxyz: np.ndarray) -> np.ndarray:
    """The rotation matrix of the Hamilton quaternion ``q_wxyz`` (w, x, y, z; normalised here)."""
    w, x, y, z = np.asarray(q_wxyz, dtype=float) / np.linalg.norm(q_wxyz)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def euler_matrix(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """The rotation of the Tait-Bryan angles (z-y'-x'', PX4's order): ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    cr, sr, cp, sp, cy, sy = (np.cos(roll_rad), np.sin(roll_rad), np.cos(pitch_rad), np.sin(pitch_rad),
                              np.cos(yaw_rad), np.sin(yaw_rad))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def euler_quaternion(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """The quaternion (w, x, y, z) of the same Tait-Bryan angles as :func:`euler_matrix`."""
    cr, sr = np.cos(roll_rad / 2), np.sin(roll_rad / 2)
    cp, sp = np.cos(pitch_rad / 2), np.sin(pitch_rad / 2)
    cy, sy = np.cos(yaw_rad / 2), np.sin(yaw_rad / 2)
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


def yaw_of(rotation_ned_x: np.ndarray) -> float:
    """The heading [rad] in NED of the x axis of the frame ``rotation_ned_x`` maps from."""
    return float(np.arctan2(rotation_ned_x[1, 0], rotation_ned_x[0, 0]))
