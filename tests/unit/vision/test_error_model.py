"""The batch's detection-error model: its draws follow its law, it sees what is in view, and the
real detector's errors on rendered frames fall inside its bands."""
from __future__ import annotations

import numpy as np

from mission.vision.detect import MarkerDetector
from mission.vision.layout import MarkerLayout
from sim.camera.error_model import FITTED, ModelledDetector, apparent_side_px
from sim.camera.render import true_marker_pose
from sim.camera.sensor import Sensor, sensor_model
from sim.camera.simulated import SimulatedCamera
from tests.unit.vision.scenes import CAMERA, aimed, random_attitudes

LAYOUT = MarkerLayout.single(0.5)


def _along(poses, measured_in_cam_m: np.ndarray) -> float:
    """The error along the camera's line of sight to the deck centre, relative to the distance [-]."""
    t = true_marker_pose(CAMERA, poses).deck_in_cam_m
    return float((measured_in_cam_m - t) @ t / (t @ t))


def test_the_model_draws_its_law():
    detector = ModelledDetector(CAMERA, LAYOUT, FITTED, seed=3)
    poses = aimed(CAMERA, 6.0, 0.0, 0.0, 0.0)
    side, tag_id = apparent_side_px(CAMERA, LAYOUT, true_marker_pose(CAMERA, poses))
    mean, sigma, _ = FITTED.predicted(side)
    draws = np.array([_along(poses, detector.measure(poses, 0.0).marker.deck_in_cam_m) for _ in range(800)])
    assert abs(draws.mean() - mean) < 4 * sigma / np.sqrt(800) and abs(draws.std() / sigma - 1) < 0.1
    m = detector.measure(poses, 1.5)
    assert m.capture_t_s == 1.5 and m.tag_ids == (tag_id,)
    assert abs(m.sigma_m - sigma * np.linalg.norm(true_marker_pose(CAMERA, poses).deck_in_cam_m)) < 1e-9


def test_the_model_sees_only_what_is_in_view():
    detector = ModelledDetector(CAMERA, LAYOUT, FITTED)
    assert detector.measure(aimed(CAMERA, 0.3, 0.0, 0.0, 0.0), 0.0) is None  # overflows the image
    assert detector.measure(aimed(CAMERA, 30.0, 0.0, 0.0, 0.0), 0.0) is None  # 6 px: too small
    assert detector.measure(aimed(CAMERA, 3.0, 0.0, 0.0, 0.0, (4.0, 0.0)), 0.0) is None  # out of the image
    assert detector.measure(aimed(CAMERA, 3.0, 0.0, 0.0, 0.0), 0.0) is not None


def test_the_real_detector_falls_inside_the_model():
    """At 5 m the detector's relative errors along the line of sight lie within the model's
    3 sigma of its mean, and their mean within 1 sigma of the model's."""
    detector = MarkerDetector(CAMERA, LAYOUT)
    camera = SimulatedCamera(CAMERA, LAYOUT, Sensor(sensor_model(dropout_probability=0.0), seed=9))
    errors, bands = [], []
    for roll, pitch, yaw in random_attitudes(21, 16, 15.0):
        poses = aimed(CAMERA, 5.0, roll, pitch, yaw)
        m = detector.measure(camera.capture(poses, 0.0).image, 0.0, poses.attitude_q_wxyz)
        assert m is not None
        side, _ = apparent_side_px(CAMERA, LAYOUT, true_marker_pose(CAMERA, poses))
        mean, sigma, _ = FITTED.predicted(side)
        errors.append(_along(poses, m.marker.deck_in_cam_m))
        bands.append((mean, sigma))
        assert abs(errors[-1] - mean) < 3 * sigma
    means, sigmas = np.array(bands).T
    assert abs(np.mean(errors) - means.mean()) < sigmas.mean()
