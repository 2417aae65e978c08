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


def matrix_quaternion(rotation: np.ndarray) -> np.ndarray:
    """The unit Hamilton quaternion (w, x, y, z, w >= 0) of the rotation matrix ``rotation``
    (the inverse of :func:`quaternion_matrix`; Shepperd's method, stable for every angle)."""
    m = np.asarray(rotation, dtype=float)
    trace = float(np.trace(m))
    diag = np.diag(m)
    k = int(np.argmax([trace, *diag]))
    if k == 0:
        w = np.sqrt(1.0 + trace) / 2
        q = np.array([w, (m[2, 1] - m[1, 2]) / (4 * w), (m[0, 2] - m[2, 0]) / (4 * w), (m[1, 0] - m[0, 1]) / (4 * w)])
    else:
        i = k - 1
        j, n = (i + 1) % 3, (i + 2) % 3
        v = np.sqrt(1.0 + m[i, i] - m[j, j] - m[n, n]) / 2
        q = np.empty(4)
        q[0] = (m[n, j] - m[j, n]) / (4 * v)
        q[1 + i] = v
        q[1 + j] = (m[j, i] + m[i, j]) / (4 * v)
        q[1 + n] = (m[n, i] + m[i, n]) / (4 * v)
    q = q / np.linalg.norm(q)
    return -q if q[0] < 0 else q


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
