"""Renders the deck's tags as a downward camera sees them: each tag (with its white margin) warped
onto the image plane by the homography of its plane, over a plain background; then the sensor's
effects (:mod:`sim.camera.sensor`). A pinhole without distortion: the simulated camera model has
none."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any

import numpy as np

from mission.vision.camera import CameraModel
from mission.core.geodesy import project
from mission.vision.frames import ROTATION_DECK_TAG, quaternion_matrix, yaw_of
from mission.vision.layout import FAMILY, TAG_BITS, MarkerLayout, Tag
from mission.vision.measurement import MarkerPose

BACKGROUND = 110  # the deck's grey [0-255]
NEAR_CLIP_M = 0.02  # a tag with a corner nearer the camera plane than this is not drawn [m]


@dataclass(frozen=True)
class Poses:
    """The truth one frame is rendered from: the vehicle's position ``vehicle_ned_m`` (3,) [m] and
    attitude ``attitude_q_wxyz`` (body -> NED); the deck centre ``deck_ned_m`` (3,) [m] and the
    carrier's yaw ``deck_yaw_rad`` [rad] (the deck level)."""

    vehicle_ned_m: np.ndarray
    attitude_q_wxyz: np.ndarray
    deck_ned_m: np.ndarray
    deck_yaw_rad: float = 0.0


def true_marker_pose(camera: CameraModel, poses: Poses) -> MarkerPose:
    """The deck in the camera frame, from the true poses and the camera's mount."""
    rotation_ned_body = quaternion_matrix(poses.attitude_q_wxyz)
    rotation_ned_cam = rotation_ned_body @ camera.mount.rotation_body_cam
    camera_ned = np.asarray(poses.vehicle_ned_m, float) + rotation_ned_body @ camera.mount.offset_body_m
    c, s = np.cos(poses.deck_yaw_rad), np.sin(poses.deck_yaw_rad)
    rotation_ned_deck = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return MarkerPose(rotation_ned_cam.T @ rotation_ned_deck,
                      rotation_ned_cam.T @ (np.asarray(poses.deck_ned_m, float) - camera_ned))


@lru_cache(maxsize=64)
def tag_image(tag_id: int, bit_px: int) -> np.ndarray:
    """The tag ``tag_id`` with a white margin of one bit, ``bit_px`` pixels a bit, uint8."""
    import cv2  # (here, not at the top: a mock vehicle without a camera imports this module for its poses)

    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, FAMILY))
    marker = cv2.aruco.generateImageMarker(dictionary, tag_id, TAG_BITS * bit_px)
    return cv2.copyMakeBorder(marker, bit_px, bit_px, bit_px, bit_px, cv2.BORDER_CONSTANT, value=255)


def render(camera: CameraModel, layout: MarkerLayout, marker: MarkerPose, background: int = BACKGROUND,
           others: Sequence[tuple[MarkerLayout, MarkerPose]] = ()) -> np.ndarray:
    """The ideal grey frame (height, width) uint8 of ``layout`` at ``marker`` (the deck in the
    camera frame), and of each of ``others`` (another marker on the deck, another slot's: its
    layout and pose) drawn first: no noise, no blur."""
    image = np.full((camera.height, camera.width), background, np.uint8)
    for other, pose in [*others, (layout, marker)]:
        for tag in sorted(other.tags, key=lambda t: -t.size_m):  # the small tags last, on top
            _draw(image, camera, tag, pose)
    return image


def other_poses(camera: CameraModel, poses: Poses,
                others: Sequence[tuple[MarkerLayout, np.ndarray]]) -> list[tuple[MarkerLayout, MarkerPose]]:
    """Each of ``others`` (a marker's layout and its centre's NED offset [m] from the marker of
    ``poses``) in the camera frame, at the same deck yaw: what :func:`render` draws beside it."""
    return [(layout, true_marker_pose(camera, replace(poses, deck_ned_m=np.asarray(poses.deck_ned_m, float)
                                                      + np.asarray(offset, float))))
            for layout, offset in others]


def _draw(image: np.ndarray, camera: CameraModel, tag: Tag, marker: MarkerPose) -> None:
    """Warps ``tag`` (with its margin) into ``image`` in place."""
    margin = (TAG_BITS + 2) / TAG_BITS  # the printed square with its white margin, in tag sizes
    corners_tag = tag.tag_points()[:, :2] * margin  # top-left, top-right, bottom-right, bottom-left
    corners_deck = np.c_[corners_tag, np.zeros(4)] @ ROTATION_DECK_TAG.T + np.array([*tag.centre_deck_m, 0.0])
    in_cam = corners_deck @ marker.rotation_cam_deck.T + marker.deck_in_cam_m
    if np.any(in_cam[:, 2] < NEAR_CLIP_M):
        return
    pixels = (in_cam[:, :2] / in_cam[:, 2:3]) * np.diag(camera.matrix)[:2] + camera.matrix[:2, 2]
    side_px = float(np.max(np.linalg.norm(pixels - np.roll(pixels, 1, axis=0), axis=1)))
    bit_px = int(np.clip(2 ** np.ceil(np.log2(max(side_px / (TAG_BITS + 2), 1.0))), 1, 64))
    source = tag_image(tag.id, bit_px)
    n = source.shape[0]
    # pixel centres: the source's outer edge is at -0.5 and n - 0.5
    source_corners = np.array([[-0.5, -0.5], [n - 0.5, -0.5], [n - 0.5, n - 0.5], [-0.5, n - 0.5]], np.float32)
    x0, y0 = np.maximum(np.floor(pixels.min(axis=0)) - 1, 0).astype(int)
    x1, y1 = np.minimum(np.ceil(pixels.max(axis=0)) + 2, [camera.width, camera.height]).astype(int)
    if x1 <= x0 or y1 <= y0:
        return
    import cv2

    # only the tag's bounding box is warped: the homography onto the box's own pixels
    homography = cv2.getPerspectiveTransform(source_corners, (pixels - [x0, y0]).astype(np.float32))
    size = (int(x1 - x0), int(y1 - y0))
    warped = cv2.warpPerspective(source, homography, size, flags=cv2.INTER_LINEAR, borderValue=0)
    mask = cv2.warpPerspective(np.full_like(source, 255), homography, size, flags=cv2.INTER_LINEAR, borderValue=0)
    # box (1 - alpha) + warped alpha, rounded, in place: the same float32 operations without a
    # temporary of the box's size for each (a tag filling the frame: half the render's time)
    alpha = mask.astype(np.float32)
    alpha /= np.float32(255.0)
    ink = warped * alpha
    np.subtract(np.float32(1.0), alpha, out=alpha)
    box = image[y0:y1, x0:x1]
    alpha *= box
    alpha += ink
    alpha += np.float32(0.5)
    np.copyto(box, alpha, casting="unsafe")


def poses_from_ground_truth(vehicle: Any, carrier: Any, deck_offset_m=(0.0, 0.0, 0.0)) -> Poses:
    """The truth of a frame from two PX4 SIH instances' HIL_STATE_QUATERNION messages (pymavlink
    messages or anything with ``lat``, ``lon`` [degE7], ``alt`` [mm], ``attitude_quaternion``
    (w, x, y, z), ``vx, vy, vz`` [cm/s]): both projected about the vehicle's own position, so the
    deck's position is relative to the vehicle (the relative vector is all the camera needs). The
    deck centre is ``deck_offset_m`` [m] from the carrier's reference point in the carrier's FRD;
    the deck level at the carrier's yaw. The blur's relative velocity:
    :func:`relative_velocity_from_ground_truth`."""
    lat0, lon0 = vehicle.lat * 1e-7, vehicle.lon * 1e-7
    north, east = project(carrier.lat * 1e-7, carrier.lon * 1e-7, lat0, lon0)
    carrier_ned = np.array([north, east, -(carrier.alt - vehicle.alt) * 1e-3])
    rotation_ned_carrier = quaternion_matrix(np.asarray(carrier.attitude_quaternion, float))
    yaw = yaw_of(rotation_ned_carrier)
    c, s = np.cos(yaw), np.sin(yaw)
    deck_ned = carrier_ned + np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.asarray(deck_offset_m, float)
    return Poses(np.zeros(3), np.asarray(vehicle.attitude_quaternion, float), deck_ned, float(yaw))


def relative_velocity_from_ground_truth(vehicle: Any, carrier: Any) -> np.ndarray:
    """The carrier's velocity minus the vehicle's [m/s] NED from their HIL_STATE_QUATERNION (cm/s)."""
    return np.array([carrier.vx - vehicle.vx, carrier.vy - vehicle.vy, carrier.vz - vehicle.vz]) * 0.01
