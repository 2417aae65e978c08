"""A detection-error model for batch simulations: the detector's measurement made from the truth,
without rendering, with the errors the real detector makes on rendered frames (fitted by
``python -m bench.vision_error_fit``, which prints the fit's quality; docs/vision.md).

The model works in the camera frame, on the line of sight ``u`` to the deck centre: with
``side_px`` the apparent side of the biggest tag wholly in view (``size f / distance``), the error
along ``u`` has a mean ``distance * bias_along * side_px**-bias_power`` (the detector sees small
tags a little too small: the deck farther) and a standard deviation ``distance * sigma_along *
side_px**-sigma_power``; across ``u`` each axis has ``distance * sigma_across *
side_px**-across_power``. A frame is seen when a tag is wholly in the image and at least
``min_side_px`` across, and the sensor did not drop it. Not modelled: the pose flip (the model's
deck orientation is the truth), occlusion, blur, and a real lens's distortion residuals."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mission.vision.camera import CameraModel
from mission.vision.frames import quaternion_matrix, yaw_of
from mission.vision.layout import MarkerLayout
from mission.vision.measurement import MarkerPose, RelativeMeasurement
from sim.camera.render import Poses, true_marker_pose


@dataclass(frozen=True)
class DetectionErrorModel:
    """The fitted coefficients (see the module): relative errors [-] and their power laws in the
    tag's apparent side [px]; ``min_side_px`` [px] the smallest tag seen; ``dropout_probability``."""

    bias_along: float = 0.0
    bias_power: float = 1.0
    sigma_along: float = 0.0
    sigma_power: float = 1.0
    sigma_across: float = 0.0
    across_power: float = 1.0
    min_side_px: float = 14.0
    dropout_probability: float = 0.0

    def predicted(self, side_px: float) -> tuple[float, float, float]:
        """(mean along, sigma along, sigma across per axis), relative to the distance [-], for a
        tag of apparent side ``side_px`` [px]."""
        return (self.bias_along * side_px ** -self.bias_power, self.sigma_along * side_px ** -self.sigma_power,
                self.sigma_across * side_px ** -self.across_power)


def apparent_side_px(camera: CameraModel, layout: MarkerLayout, marker: MarkerPose) -> tuple[float, int] | None:
    """The apparent side [px] and the id of the biggest tag of ``layout`` wholly in the image
    (with its white margin) at ``marker``, or None: none is."""
    best: tuple[float, int] | None = None
    margin = 10 / 8
    for tag in layout.tags:
        corners = tag.deck_points()
        centre = np.array([*tag.centre_deck_m, 0.0])
        in_cam = (centre + (corners - centre) * margin) @ marker.rotation_cam_deck.T + marker.deck_in_cam_m
        if np.any(in_cam[:, 2] <= 0.02):
            continue
        pixels = in_cam[:, :2] / in_cam[:, 2:3] * np.diag(camera.matrix)[:2] + camera.matrix[:2, 2]
        if np.any(pixels < 0) or np.any(pixels[:, 0] > camera.width - 1) or np.any(pixels[:, 1] > camera.height - 1):
            continue
        side = float(np.min(np.linalg.norm(pixels - np.roll(pixels, 1, axis=0), axis=1))) / margin
        if best is None or side > best[0]:
            best = (side, tag.id)
    return best


@dataclass
class ModelledDetector:
    """Measurements of the deck from the true poses through ``model``, with its own seeded stream."""

    camera: CameraModel
    layout: MarkerLayout
    model: DetectionErrorModel
    seed: int = 0

    def __post_init__(self) -> None:
        self._rng = np.random.default_rng(self.seed)

    def measure(self, poses: Poses, capture_t_s: float) -> RelativeMeasurement | None:
        marker = true_marker_pose(self.camera, poses)
        seen = apparent_side_px(self.camera, self.layout, marker)
        if seen is None or seen[0] < self.model.min_side_px or self._rng.random() < self.model.dropout_probability:
            return None
        side, tag_id = seen
        t = marker.deck_in_cam_m
        distance = float(np.linalg.norm(t))
        u = t / distance
        mean_along, sigma_along, sigma_across = (distance * k for k in self.model.predicted(side))
        across = self._rng.normal(0.0, sigma_across, 3)
        across -= (across @ u) * u
        measured = t + (mean_along + self._rng.normal(0.0, sigma_along)) * u + across
        covariance_cam = sigma_along ** 2 * np.outer(u, u) + sigma_across ** 2 * (np.eye(3) - np.outer(u, u))
        mount = self.camera.mount
        rotation_ned_body = quaternion_matrix(poses.attitude_q_wxyz)
        rotation_ned_cam = rotation_ned_body @ mount.rotation_body_cam
        deck_body = mount.rotation_body_cam @ measured + mount.offset_body_m
        return RelativeMeasurement(
            capture_t_s=float(capture_t_s), deck_rel_ned_m=rotation_ned_body @ deck_body,
            covariance_ned_m2=rotation_ned_cam @ covariance_cam @ rotation_ned_cam.T, deck_body_frd_m=deck_body,
            attitude_q_wxyz=np.asarray(poses.attitude_q_wxyz, float),
            deck_yaw_ned_rad=yaw_of(rotation_ned_cam @ marker.rotation_cam_deck), tag_ids=(tag_id,),
            reprojection_error_px=float("nan"), marker=MarkerPose(marker.rotation_cam_deck, measured))


# Fitted by `python -m bench.vision_error_fit --frames 400` on 2026-12-03 (OpenCV 5.1.0); the
# fit's quality on held-out frames: docs/vision.md.
FITTED = DetectionErrorModel(bias_along=1.072, bias_power=1.370, sigma_along=1.106, sigma_power=1.506,
                             sigma_across=6.30e-4, across_power=0.228, min_side_px=14.0)
