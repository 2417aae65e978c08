"""A real camera: grey frames from ``cv2.VideoCapture`` (a device, a file or a GStreamer
pipeline), each with its capture time, and its calibration file read. Thin I/O: no detection
here (:mod:`mission.vision.detect`). How to point it at a camera: docs/vision.md."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from mission.errors import MarsupialError
from mission.vision.camera import OPENCV_ALIASES, CameraModel, Frame, Mount, calibrated, plain_json, ros_yaml


class CameraError(MarsupialError):
    """The camera cannot be opened or stopped delivering frames."""


def open_capture(source: str) -> cv2.VideoCapture:
    """``source``: a device index ("0"), a device path ("/dev/video0"), a video file, a stream URL
    (rtsp://...) or a GStreamer pipeline ending in ``appsink`` (read with OpenCV's GStreamer
    backend, which the OpenCV build must have)."""
    if source.isdigit():
        capture = cv2.VideoCapture(int(source))
    elif "appsink" in source:
        capture = cv2.VideoCapture(source, cv2.CAP_GSTREAMER)
    else:
        capture = cv2.VideoCapture(source)
    if not capture.isOpened():
        raise CameraError(f"cannot open the camera {source!r}")
    return capture


class CameraSource:
    """Frames from ``source`` (:func:`open_capture`), stamped with ``clock()`` [s] at the grab minus
    ``latency_s`` [s] (the camera's known exposure-to-delivery delay, measured once; a file's frames
    are stamped with their position in the file instead). A context manager: leaving it releases
    the camera."""

    def __init__(self, source: str, latency_s: float = 0.0, clock: Callable[[], float] = time.monotonic):
        self._capture = open_capture(source)
        self._latency_s = latency_s
        self._clock = clock
        self._is_file = not source.isdigit() and "://" not in source and "appsink" not in source \
            and not source.startswith("/dev/")

    def read(self) -> Frame | None:
        """The next frame, or None at the end of a file. Raises CameraError if a live camera fails."""
        if not self._capture.grab():
            if self._is_file:
                return None
            raise CameraError("the camera stopped delivering frames")
        t_s = (self._capture.get(cv2.CAP_PROP_POS_MSEC) / 1000.0 if self._is_file
               else self._clock() - self._latency_s)
        ok, image = self._capture.retrieve()
        if not ok:
            raise CameraError("the camera's frame could not be decoded")
        if image.ndim == 3:
            image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        return Frame(image, t_s)

    def close(self) -> None:
        self._capture.release()

    def __enter__(self) -> CameraSource:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def load_calibration(path: str | Path, mount: Mount | None = None) -> CameraModel:
    """A camera model from a calibration file: OpenCV's own (YAML, XML or JSON written by
    ``cv2.FileStorage``, as OpenCV's calibration tutorial and its interactive calibration tool
    write it: ``camera_matrix``, ``distortion_coefficients``, ``image_width``, ``image_height``,
    or their other spellings there), a plain JSON object with the
    same keys as lists, or ROS's ``camera_info`` YAML (``camera_matrix: {data: [...]}``,
    ``distortion_coefficients: {data: [...]}``). Raises ValueError naming what is missing."""
    path = Path(path)
    text = path.read_text()
    values = plain_json(text) if path.suffix == ".json" else None
    if values is None:
        values = _opencv_storage(path) if text.lstrip().startswith(("%YAML", "<?xml", "{")) else ros_yaml(text)
    return calibrated(values, mount, str(path))


def _opencv_storage(path: Path) -> dict:
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        values = {}
        for key, names in OPENCV_ALIASES.items():
            for name in names:
                node = storage.getNode(name)
                if not node.empty():
                    values[key] = node.mat() if node.isMap() else node.real()
                    break
        resolution = storage.getNode("cameraResolution")
        if not resolution.empty() and "image_width" not in values:
            size = resolution.mat() if resolution.isMap() else [resolution.at(i).real() for i in range(resolution.size())]
            values["image_width"], values["image_height"] = np.ravel(size)[:2]
        return values
    finally:
        storage.release()
