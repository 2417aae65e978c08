"""The camera model: a pinhole with OpenCV's distortion, its image size, and where it is mounted on
the vehicle. Made from a field of view (the simulated camera) or from a calibration's values (a real one:
the file is read by :func:`mission.vision.capture.load_calibration`). The file formats:
docs/vision.md."""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field

import numpy as np

from mission.vision.frames import ROTATION_BODY_CAM_DOWN, euler_matrix


@dataclass(frozen=True)
class Frame:
    """One grey frame ``image`` (H, W) uint8 and ``capture_t_s`` [s]: when it was exposed, on the
    clock of its source (a real camera's grab time minus its latency, or the simulator's time)."""

    image: np.ndarray
    capture_t_s: float


@dataclass(frozen=True)
class SeenFrame:
    """A frame as a marker feed saw it: ``image`` (H, W) uint8 grey, ``capture_t_s`` [s] on the
    mission clock, the ``camera`` it was measured with (:class:`CameraModel`), the tags found in
    it (``ids`` (n,), ``corners`` (n, 4, 2) [px, OpenCV's pixel-centre coordinates]) and whether a
    reading of the deck came of it (``measured``: its pose passed the gates)."""

    image: np.ndarray
    capture_t_s: float
    camera: CameraModel
    ids: np.ndarray
    corners: np.ndarray
    measured: bool


@dataclass(frozen=True)
class Mount:
    """Where the camera sits on the vehicle: ``offset_body_m`` (3,) its optical centre in body FRD
    [m]; ``rotation_body_cam`` (3, 3) its axes in body FRD (camera -> body)."""

    offset_body_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation_body_cam: np.ndarray = field(default_factory=lambda: ROTATION_BODY_CAM_DOWN.copy())

    @classmethod
    def downward(cls, offset_body_m=(0.0, 0.0, 0.0), roll_deg: float = 0.0, pitch_deg: float = 0.0,
                 yaw_deg: float = 0.0) -> Mount:
        """A downward camera at ``offset_body_m`` [m] FRD, turned from the nominal downward mount
        (image top forward) by the body-frame Tait-Bryan angles [deg]."""
        turn = euler_matrix(*np.radians([roll_deg, pitch_deg, yaw_deg]))
        return cls(np.asarray(offset_body_m, dtype=float), turn @ ROTATION_BODY_CAM_DOWN)


@dataclass(frozen=True)
class CameraModel:
    """A pinhole camera: ``matrix`` (3, 3) OpenCV's camera matrix [px], ``distortion`` (k1, k2, p1,
    p2[, k3...]) OpenCV's distortion coefficients, the image ``width``, ``height`` [px], and its
    ``mount`` on the vehicle."""

    matrix: np.ndarray
    distortion: np.ndarray
    width: int
    height: int
    mount: Mount = field(default_factory=Mount)

    @classmethod
    def from_fov(cls, width: int = 640, height: int = 480, hfov_deg: float = 80.0, mount: Mount | None = None) -> CameraModel:
        """An ideal camera (square pixels, centred, no distortion) of horizontal field of view
        ``hfov_deg`` [deg]."""
        f = (width / 2) / np.tan(np.radians(hfov_deg) / 2)
        matrix = np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1.0]])
        return cls(matrix, np.zeros(5), width, height, mount or Mount())

    @property
    def focal_px(self) -> float:
        """The mean focal length [px]."""
        return float((self.matrix[0, 0] + self.matrix[1, 1]) / 2)

    def fov_deg(self) -> tuple[float, float]:
        """The horizontal and vertical fields of view [deg] (of the pinhole, distortion aside)."""
        return (float(np.degrees(2 * np.arctan(self.width / 2 / self.matrix[0, 0]))),
                float(np.degrees(2 * np.arctan(self.height / 2 / self.matrix[1, 1]))))

    def with_mount(self, mount: Mount) -> CameraModel:
        return CameraModel(self.matrix, self.distortion, self.width, self.height, mount)


def calibrated(values: dict, mount: Mount | None = None, source: str = "the calibration") -> CameraModel:
    """A camera model from a calibration's values (``camera_matrix``, ``distortion_coefficients``,
    ``image_width``, ``image_height``: what :func:`plain_json`, :func:`ros_yaml` or OpenCV's
    ``FileStorage`` read; the file itself is read by :func:`mission.vision.capture.load_calibration`).
    Raises ValueError naming what is missing, and ``source``."""
    try:
        matrix = np.asarray(values["camera_matrix"], dtype=float).reshape(3, 3)
        distortion = np.asarray(values["distortion_coefficients"], dtype=float).ravel()
        width, height = int(values["image_width"]), int(values["image_height"])
    except KeyError as missing:
        raise ValueError(f"{source}: no {missing.args[0]}") from None
    if matrix[0, 0] <= 0 or matrix[1, 1] <= 0 or width <= 0 or height <= 0:
        raise ValueError(f"{source}: camera_matrix and image size must be positive")
    return CameraModel(matrix, distortion, width, height, mount or Mount())


def plain_json(text: str) -> dict | None:
    """A plain JSON calibration's values; None: it is ``cv2.FileStorage``'s JSON (OpenCV reads it)."""
    data = json.loads(text)
    if isinstance(data.get("camera_matrix"), dict):  # cv2.FileStorage's JSON: {"rows", "cols", "data"}
        return None
    return data


# The names OpenCV's calibration programs write the same values under: its camera calibration
# tutorial (old and new), its interactive calibration tool (``cameraResolution`` = [w, h]).
OPENCV_ALIASES = {"camera_matrix": ("camera_matrix", "Camera_Matrix", "cameraMatrix"),
                  "distortion_coefficients": ("distortion_coefficients", "Distortion_Coefficients", "dist_coeffs"),
                  "image_width": ("image_width", "image_Width"), "image_height": ("image_height", "image_Height")}


def ros_yaml(text: str) -> dict:
    """ROS's camera_info YAML, read without a YAML library: the keys this module needs only."""
    values: dict = {}
    for name in ("image_width", "image_height"):
        found = re.search(rf"^{name}:\s*(\d+)", text, re.M)
        if found:
            values[name] = float(found.group(1))
    for name in ("camera_matrix", "distortion_coefficients"):
        found = re.search(rf"^{name}:\s*\n(?:[ \t]+\w+:[^\n]*\n)*?[ \t]+data:\s*\[([^\]]*)\]", text, re.M)
        if found:
            values[name] = [float(v) for v in found.group(1).split(",") if v.strip()]
    return values
