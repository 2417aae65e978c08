"""The detector: AprilTag 36h11 corners in a grey image (OpenCV's aruco module), the deck's pose
from them (``solvePnP``'s ``IPPE_SQUARE`` per tag, both of its solutions weighed; all the tags seen
refined together) and the relative measurement (:mod:`mission.vision.measurement`). Pure: an image
and an attitude in, a measurement or None out."""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import cv2
import numpy as np

from mission.vision.camera import CameraModel
from mission.vision.frames import ROTATION_DECK_TAG, quaternion_matrix, yaw_of
from mission.vision.layout import FAMILY, MarkerLayout
from mission.vision.measurement import MarkerPose, RelativeMeasurement


@dataclass(frozen=True)
class DetectorSettings:
    """max_tilt_deg: the flip gate: a pose whose deck normal is further than this from the NED
    vertical (through the attitude used) is rejected [deg]; ambiguity_ratio: when IPPE's second
solution's reprojection error is within this factor of the first's, the pose is ambiguous (a far
or frontal tag) and the more level of the two wins; max_reprojection_px: a pose whose RMS
    reprojection error is above this is rejected [px]; pixel_sigma_px: the corner noise floor the
    covariance assumes [px] (the RMS reprojection error when larger); min_side_px: tags whose
    shortest side is below this in the image are ignored [px]; subpixel: refine the corners to a
    sub-pixel (OpenCV's ``CORNER_REFINE_SUBPIX``); decimate: look for tags in an image this many
    times smaller, then refine their corners at full resolution (1: off); threshold_windows_px:
    the adaptive threshold's window sizes (smallest, largest, step) [px], one pass each (OpenCV's
    ``adaptiveThreshWinSize*``). The gates ``[vision]`` configures (``max_tilt_deg``,
    ``max_reprojection_px``) have no default here: the schema holds it (:func:`schema_settings`)."""

    max_tilt_deg: float
    max_reprojection_px: float
    ambiguity_ratio: float = 3.0
    pixel_sigma_px: float = 0.3
    min_side_px: float = 12.0
    subpixel: bool = True
    decimate: int = 1
    threshold_windows_px: tuple[int, int, int] = (3, 23, 10)


@dataclass(frozen=True)
class Corners:
    """What the bare detector found: ``ids`` (n,) and ``corners`` (n, 4, 2) [px], full-image pixels."""

    ids: np.ndarray
    corners: np.ndarray


def schema_settings(**overrides: Any) -> DetectorSettings:
    """The settings of the schema's default ``[vision]`` (each field it has by the same name),
    with ``overrides``; a configuration's own: ``mission.model.vision_detector``."""
    from mission.config.vision import VisionSection

    v = VisionSection()
    named = {f.name: getattr(v, f.name) for f in fields(DetectorSettings) if f.name in type(v).model_fields}
    return DetectorSettings(**{**named, **overrides})


class MarkerDetector:
    """Detects ``layout``'s tags in ``camera``'s images and measures the deck from them."""

    def __init__(self, camera: CameraModel, layout: MarkerLayout, settings: DetectorSettings | None = None):
        self.camera = camera
        self.layout = layout
        self.settings = settings or schema_settings()
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = (cv2.aruco.CORNER_REFINE_SUBPIX if self.settings.subpixel
                                         and self.settings.decimate == 1 else cv2.aruco.CORNER_REFINE_NONE)
        (params.adaptiveThreshWinSizeMin, params.adaptiveThreshWinSizeMax,
         params.adaptiveThreshWinSizeStep) = self.settings.threshold_windows_px
        self._detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, FAMILY)), params)

    def corners(self, grey: np.ndarray, roi: tuple[int, int, int, int] | None = None) -> Corners:
        """The layout's tags found in ``grey`` (H, W) uint8, only in ``roi`` (x0, y0, x1, y1) [px]
        when given; other ids and tags smaller than ``min_side_px`` are dropped."""
        x0, y0 = 0, 0
        if roi is not None:
            x0, y0, x1, y1 = roi
            grey = grey[y0:y1, x0:x1]
        k = self.settings.decimate
        small = grey if k == 1 else cv2.resize(grey, (grey.shape[1] // k, grey.shape[0] // k), interpolation=cv2.INTER_AREA)
        found, ids, _ = self._detector.detectMarkers(small)
        if ids is None or len(ids) == 0:  # OpenCV 4: None; 5: empty
            return Corners(np.zeros(0, int), np.zeros((0, 4, 2)))
        corners = np.asarray(found, dtype=float).reshape(-1, 4, 2)
        if k > 1:
            corners = (corners + 0.5) * k - 0.5  # pixel centres of the small image in the full one
            if self.settings.subpixel:
                refined = cv2.cornerSubPix(grey, np.ascontiguousarray(corners.reshape(-1, 1, 2), dtype=np.float32),
                                           (k + 2, k + 2), (-1, -1),
                                           (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01))
                corners = refined.reshape(-1, 4, 2).astype(float)
        corners = corners + np.array([x0, y0])
        ids = ids.ravel()
        sides = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).min(axis=1)
        keep = np.array([self.layout.tag(int(i)) is not None for i in ids], dtype=bool) & (sides >= self.settings.min_side_px)
        return Corners(ids[keep], corners[keep])

    def measure(self, grey: np.ndarray, capture_t_s: float, attitude_q_wxyz: np.ndarray,
                roi: tuple[int, int, int, int] | None = None) -> RelativeMeasurement | None:
        """The deck measured in the frame ``grey`` exposed at ``capture_t_s`` [s] with the vehicle
        at attitude ``attitude_q_wxyz`` (body -> NED); None when no tag of the layout is seen or
        the pose fails its gates (a flipped or tilted pose, a large reprojection error)."""
        return self.measure_corners(self.corners(grey, roi), capture_t_s, attitude_q_wxyz)

    def measure_corners(self, found: Corners, capture_t_s: float, attitude_q_wxyz: np.ndarray) -> RelativeMeasurement | None:
        """:meth:`measure` from corners already found."""
        if len(found.ids) == 0:
            return None
        rotation_ned_cam = quaternion_matrix(attitude_q_wxyz) @ self.camera.mount.rotation_body_cam
        biggest = int(np.argmax([cv2.contourArea(c.astype(np.float32)) for c in found.corners]))
        pose = self._square_pose(int(found.ids[biggest]), found.corners[biggest], rotation_ned_cam)
        if pose is None:
            return None
        deck_points = np.concatenate([self.layout.tag(int(i)).deck_points() for i in found.ids])  # type: ignore[union-attr]
        image_points = found.corners.reshape(-1, 2)
        rvec, tvec = pose
        if len(found.ids) > 1:
            rvec, tvec = cv2.solvePnPRefineLM(deck_points, image_points, self.camera.matrix, self.camera.distortion,
                                              rvec.copy(), tvec.copy())
        rotation_cam_deck = cv2.Rodrigues(rvec)[0]
        if self._tilt_deg(rotation_ned_cam @ rotation_cam_deck) > self.settings.max_tilt_deg:
            return None
        projected, jacobian = cv2.projectPoints(deck_points, rvec, tvec, self.camera.matrix, self.camera.distortion)
        residual = projected.reshape(-1, 2) - image_points
        rms_px = float(np.sqrt(np.mean(np.sum(residual ** 2, axis=1))))
        if rms_px > self.settings.max_reprojection_px:
            return None
        return self._measurement(capture_t_s, attitude_q_wxyz, found.ids, rotation_cam_deck, tvec.ravel(), rms_px,
                                 jacobian[:, :6])

    def _square_pose(self, tag_id: int, corners: np.ndarray, rotation_ned_cam: np.ndarray):
        """The deck's pose (rvec, tvec) from one tag: of IPPE's two solutions, those whose deck
        normal passes the tilt gate; of those, the one with the smaller reprojection error, or the
        more level one when their errors are within ``ambiguity_ratio``; None if neither passes."""
        tag = self.layout.tag(tag_id)
        assert tag is not None
        _, rvecs, tvecs, errors = cv2.solvePnPGeneric(tag.tag_points(), corners, self.camera.matrix,
                                                      self.camera.distortion, flags=cv2.SOLVEPNP_IPPE_SQUARE)
        candidates = []  # (reprojection error [px], tilt [deg], rotation_cam_deck, tvec of the tag)
        for rvec, tvec, error in zip(rvecs, tvecs, np.ravel(errors)):
            rotation_cam_deck = cv2.Rodrigues(rvec)[0] @ ROTATION_DECK_TAG.T
            tilt = self._tilt_deg(rotation_ned_cam @ rotation_cam_deck)
            if tilt <= self.settings.max_tilt_deg:
                candidates.append((float(error), tilt, rotation_cam_deck, tvec.ravel()))
        if not candidates:
            return None
        candidates.sort(key=lambda c: c[0])
        if len(candidates) > 1 and candidates[1][0] < self.settings.ambiguity_ratio * max(candidates[0][0], 1e-9):
            candidates.sort(key=lambda c: c[1])  # ambiguous: the deck is more nearly level than not
        _, _, rotation_cam_deck, tvec = candidates[0]
        centre = np.array([*tag.centre_deck_m, 0.0])
        return cv2.Rodrigues(rotation_cam_deck)[0], (tvec - rotation_cam_deck @ centre).reshape(3, 1)

    @staticmethod
    def _tilt_deg(rotation_ned_deck: np.ndarray) -> float:
        """The angle between the deck's down axis and NED's down [deg]."""
        return float(np.degrees(np.arccos(np.clip(rotation_ned_deck[2, 2], -1.0, 1.0))))

    def _measurement(self, capture_t_s: float, attitude_q_wxyz: np.ndarray, ids: np.ndarray,
                     rotation_cam_deck: np.ndarray, deck_in_cam_m: np.ndarray, rms_px: float,
                     jacobian: np.ndarray) -> RelativeMeasurement:
        mount = self.camera.mount
        rotation_ned_body = quaternion_matrix(attitude_q_wxyz)
        rotation_ned_cam = rotation_ned_body @ mount.rotation_body_cam
        deck_body = mount.rotation_body_cam @ deck_in_cam_m + mount.offset_body_m
        sigma_px = max(self.settings.pixel_sigma_px, rms_px)
        information = jacobian.T @ jacobian
        covariance_cam = sigma_px ** 2 * np.linalg.pinv(information)[3:6, 3:6]
        return RelativeMeasurement(
            capture_t_s=float(capture_t_s),
            deck_rel_ned_m=rotation_ned_body @ deck_body,
            covariance_ned_m2=rotation_ned_cam @ covariance_cam @ rotation_ned_cam.T,
            deck_body_frd_m=deck_body,
            attitude_q_wxyz=np.asarray(attitude_q_wxyz, dtype=float),
            deck_yaw_ned_rad=yaw_of(rotation_ned_cam @ rotation_cam_deck),
            tag_ids=tuple(sorted(int(i) for i in ids)),
            reprojection_error_px=rms_px,
            marker=MarkerPose(rotation_cam_deck, deck_in_cam_m.copy()))


def predicted_roi(camera: CameraModel, layout: MarkerLayout, marker: MarkerPose, margin: float = 0.5) -> tuple[int, int, int, int]:
    """A region of interest (x0, y0, x1, y1) [px] around where ``marker`` puts the layout's tags,
    grown by ``margin`` times its size each side and clipped to the image: where to look next."""
    points = np.concatenate([t.deck_points() for t in layout.tags])
    projected, _ = cv2.projectPoints(points, cv2.Rodrigues(marker.rotation_cam_deck)[0], marker.deck_in_cam_m,
                                     camera.matrix, camera.distortion)
    lo, hi = projected.reshape(-1, 2).min(axis=0), projected.reshape(-1, 2).max(axis=0)
    grow = (hi - lo) * margin + 8
    x0, y0 = np.maximum(lo - grow, 0).astype(int)
    x1, y1 = np.minimum(hi + grow, [camera.width, camera.height]).astype(int)
    return int(x0), int(y0), int(x1), int(y1)
