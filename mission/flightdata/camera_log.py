"""The passenger camera in ``flight.mcap``: what the marker feed saw, as Foxglove messages.

Each :class:`SeenFrame` the feed hands over (at most ``vision.log_rate_hz`` a second) becomes,
at its arrival time on the mission clock (the log time; the messages' own timestamp is the
frame's capture time, as a ROS ``header.stamp``):

- ``/<pair>/camera/image``: ``foxglove.CompressedImage``, the grey frame as JPEG;
- ``/<pair>/camera/calibration``: ``foxglove.CameraCalibration``, the pinhole and OpenCV's
  ``plumb_bob`` distortion the detector used, so Foxglove's Image panel can project with it;
- ``/<pair>/camera/detections``: ``foxglove.ImageAnnotations``, each found tag's corners (a closed
  line, in pixels with the top-left corner of the top-left pixel as the origin, as Foxglove
  draws them; OpenCV puts pixel centres on integers) and its id, empty when none was found;
- ``/<pair>/tf/camera``: the camera's mount, ``<pair>/passenger/base_link_frd`` ->
  ``<pair>/passenger/camera_optical`` (:func:`mission.flightdata.topics.camera_frame`), with the
  first frame and then once a second.

Topics: :data:`mission.flightdata.topics.CAMERA_CHANNELS`. The channels exist only in flights
that logged a frame.
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from mission.flightdata.topics import CAMERA_CHANNELS, camera_frame, frame, topics
from mission.vision.camera import CameraModel, SeenFrame
from mission.vision.frames import matrix_quaternion

JPEG_QUALITY = 90  # [0-100] OpenCV's JPEG quality: a 640 x 480 rendered frame is 20-40 kB
MOUNT_PERIOD_S = 1.0  # [s] of mission clock between two mount transforms
CORNER_COLOUR = (0.2, 0.9, 0.3, 1.0)  # RGBA 0-1: the found tag's outline


def jpeg(image: np.ndarray, quality: int = JPEG_QUALITY) -> bytes:
    """``image`` (uint8, grey or BGR) as JPEG bytes (OpenCV)."""
    import cv2

    ok, data = cv2.imencode(".jpg", np.ascontiguousarray(image, dtype=np.uint8), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError(f"OpenCV could not encode a {image.shape} image as JPEG")
    return bytes(data.tobytes())


def projection(camera: CameraModel) -> list[float]:
    """The 3 x 4 projection matrix ``P`` of ``camera`` (row-major): its camera matrix with a zero
    column, as ROS's ``camera_info`` has it for a monocular camera."""
    return [float(v) for v in np.hstack([camera.matrix, np.zeros((3, 1))]).ravel()]


def plumb_bob(distortion: np.ndarray) -> list[float]:
    """OpenCV's distortion coefficients as ``plumb_bob``'s five (k1, k2, p1, p2, k3), padded with
    zeros; a model with more terms is cut to these five (Foxglove's ``rational_polynomial`` would
    need eight)."""
    d = [float(v) for v in np.asarray(distortion, dtype=float).ravel()[:5]]
    return d + [0.0] * (5 - len(d))


class CameraLog:
    """The camera's channels of one flight's log, made on the first frame. ``channel(topic,
    schema)`` makes a channel (:meth:`mission.flightdata.writer.DataLog.channel`); ``log_ns`` turns
    a mission-clock time [s] into a log time [ns]."""

    def __init__(self, pair: str, channel: Callable[[str, str], Any], log_ns: Callable[[float], int]) -> None:
        self.pair = pair
        self._channel = channel
        self._log_ns = log_ns
        self._ch: dict[str, Any] | None = None
        self._next_mount_s: float | None = None
        self.optical = camera_frame(pair)
        self.frames = 0

    def handle(self, t_s: float, item: SeenFrame) -> None:
        """Log ``item``, which arrived at ``t_s`` [s, mission clock] (the worker's thread)."""
        from foxglove.messages import (CameraCalibration, Color, CompressedImage, ImageAnnotations, Point2,
                                       PointsAnnotation, PointsAnnotationType, TextAnnotation)

        from mission.flightdata.writer import timestamp

        if self._ch is None:
            names = topics(self.pair, CAMERA_CHANNELS)
            self._ch = {key: self._channel(names[key], schema) for key, _, schema in CAMERA_CHANNELS}
        log_time = self._log_ns(t_s)
        stamp = timestamp(self._log_ns(item.capture_t_s))
        cam = item.camera
        if self._next_mount_s is None or t_s >= self._next_mount_s:
            self._mount(stamp, log_time, cam)
            self._next_mount_s = t_s + MOUNT_PERIOD_S
        self._ch["image"].log(CompressedImage(timestamp=stamp, frame_id=self.optical, data=jpeg(item.image), format="jpeg"),
                              log_time=log_time)
        self._ch["calibration"].log(CameraCalibration(
            timestamp=stamp, frame_id=self.optical, width=int(cam.width), height=int(cam.height),
            distortion_model="plumb_bob", D=plumb_bob(cam.distortion), K=[float(v) for v in cam.matrix.ravel()],
            R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], P=projection(cam)), log_time=log_time)
        colour = Color(r=CORNER_COLOUR[0], g=CORNER_COLOUR[1], b=CORNER_COLOUR[2], a=CORNER_COLOUR[3])
        outlines, labels = [], []
        for tag, corners in zip(item.ids, item.corners):
            points = [Point2(x=float(x) + 0.5, y=float(y) + 0.5) for x, y in np.asarray(corners, dtype=float)]
            outlines.append(PointsAnnotation(timestamp=stamp, type=PointsAnnotationType.LineLoop, points=points,
                                             outline_color=colour, thickness=2.0))
            labels.append(TextAnnotation(timestamp=stamp, position=points[0],
                                         text=f"tag {int(tag)}" + ("" if item.measured else " (pose rejected)"),
                                         font_size=14.0, text_color=colour))
        self._ch["detections"].log(ImageAnnotations(points=outlines, texts=labels), log_time=log_time)
        self.frames += 1

    def _mount(self, stamp: Any, log_time: int, cam: CameraModel) -> None:
        from foxglove.messages import FrameTransform, Quaternion, Vector3

        assert self._ch is not None
        w, x, y, z = matrix_quaternion(cam.mount.rotation_body_cam)
        ox, oy, oz = (float(v) for v in cam.mount.offset_body_m)
        self._ch["mount_tf"].log(FrameTransform(timestamp=stamp, parent_frame_id=frame(self.pair, "passenger"),
                                                child_frame_id=self.optical, translation=Vector3(x=ox, y=oy, z=oz),
                                                rotation=Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))),
                                 log_time=log_time)
