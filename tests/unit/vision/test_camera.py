"""The camera model (field of view, calibration files), the sensor's blur, and the real-camera
source reading a video file."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from mission.vision.camera import CameraModel, Mount
from mission.vision.capture import load_calibration
from mission.vision.capture import CameraError, CameraSource
from mission.vision.detect import MarkerDetector
from mission.vision.layout import MarkerLayout
from sim.camera.render import true_marker_pose
from sim.camera.sensor import Sensor, sensor_model, image_motion_px, line_kernel
from sim.camera.simulated import SimulatedCamera
from tests.unit.vision.scenes import CAMERA, aimed, truth

MATRIX = np.array([[400.0, 0, 321.5], [0, 401.0, 239.0], [0, 0, 1]])
DISTORTION = np.array([-0.1, 0.02, 0.001, -0.002, 0.0])


def test_field_of_view_round_trip():
    camera = CameraModel.from_fov(640, 480, 70.0)
    hfov, vfov = camera.fov_deg()
    assert hfov == pytest.approx(70.0) and vfov == pytest.approx(np.degrees(2 * np.arctan(0.75 * np.tan(np.radians(35)))))


def test_the_mount_turns_the_camera():
    assert np.allclose(Mount.downward().rotation_body_cam[:, 2], [0, 0, 1])  # looks down
    assert np.allclose(Mount.downward().rotation_body_cam[:, 1], [-1, 0, 0])  # image top forward
    tilted = Mount.downward(pitch_deg=30.0)  # pitched up 30 deg as a nose-up vehicle: looks forward-down
    assert np.allclose(tilted.rotation_body_cam[:, 2], [np.sin(np.radians(30)), 0, np.cos(np.radians(30))])


def _check(camera: CameraModel):
    assert np.allclose(camera.matrix, MATRIX) and np.allclose(camera.distortion, DISTORTION)
    assert (camera.width, camera.height) == (640, 480)


def test_opencv_calibration_files(tmp_path):
    for suffix in ("yaml", "xml", "json"):
        path = tmp_path / f"cam.{suffix}"
        storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        storage.write("image_width", 640)
        storage.write("image_height", 480)
        storage.write("camera_matrix", MATRIX)
        storage.write("distortion_coefficients", DISTORTION.reshape(1, 5))
        storage.release()
        _check(load_calibration(path))


def test_the_interactive_calibration_tools_names(tmp_path):
    path = tmp_path / "cameraParameters.xml"
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    storage.write("cameraResolution", np.array([640, 480]))
    storage.write("cameraMatrix", MATRIX)
    storage.write("dist_coeffs", DISTORTION.reshape(5, 1))
    storage.release()
    _check(load_calibration(path))


def test_plain_json_and_ros_calibration_files(tmp_path):
    plain = tmp_path / "cam.json"
    plain.write_text(json.dumps({"camera_matrix": MATRIX.tolist(), "distortion_coefficients": DISTORTION.tolist(),
                                 "image_width": 640, "image_height": 480}))
    _check(load_calibration(plain))
    ros = tmp_path / "ost.yaml"
    ros.write_text("image_width: 640\nimage_height: 480\ncamera_name: narrow_stereo\ncamera_matrix:\n  rows: 3\n"
                   "  cols: 3\n  data: [400.0, 0.0, 321.5,\n         0.0, 401.0, 239.0, 0.0, 0.0, 1.0]\n"
                   "distortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n"
                   "  data: [-0.1, 0.02, 0.001, -0.002, 0.0]\n")
    _check(load_calibration(ros))
    broken = tmp_path / "broken.json"
    broken.write_text(json.dumps({"camera_matrix": MATRIX.tolist(), "image_width": 640, "image_height": 480}))
    with pytest.raises(ValueError, match="distortion_coefficients"):
        load_calibration(broken)


def test_blur_follows_the_image_motion():
    marker = true_marker_pose(CAMERA, aimed(CAMERA, 2.0, 0.0, 0.0, 0.0))
    motion = image_motion_px(CAMERA, marker, np.array([2.0, 0.0, 0.0]), 0.01)  # 2 m/s across, 10 ms
    assert motion == pytest.approx([CAMERA.matrix[0, 0] * 2.0 * 0.01 / marker.deck_in_cam_m[2], 0.0], abs=0.05)
    kernel = line_kernel(np.array([6.0, 0.0]))
    assert kernel.sum() == pytest.approx(1.0) and kernel.shape == (7, 7) and np.count_nonzero(kernel[3]) == 7


def test_a_moderately_blurred_frame_still_measures():
    layout = MarkerLayout.single(0.5)
    poses = aimed(CAMERA, 2.0, 5.0, 0.0, 0.0)
    sensor = Sensor(sensor_model(exposure_s=0.01, dropout_probability=0.0), seed=1)
    frame = SimulatedCamera(CAMERA, layout, sensor).capture(poses, 0.0, relative_velocity_ned_m_s=(1.5, 0.5, 0.0))
    m = MarkerDetector(CAMERA, layout).measure(frame.image, 0.0, poses.attitude_q_wxyz)
    assert m is not None and np.linalg.norm(m.deck_rel_ned_m - truth(poses)) < 0.05


def test_the_real_camera_source_reads_a_file(tmp_path):
    """The same detector on frames read back through cv2.VideoCapture from a video file, stamped
    with their time in the file."""
    layout = MarkerLayout.single(0.5)
    camera = SimulatedCamera(CAMERA, layout, Sensor(sensor_model(dropout_probability=0.0)))
    path = tmp_path / "deck.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 20.0, (640, 480), isColor=False)
    poses = [aimed(CAMERA, 1.0 + 0.2 * i, 0.0, 0.0, 10.0 * i) for i in range(5)]
    for p in poses:
        writer.write(camera.capture(p, 0.0).image)
    writer.release()
    detector = MarkerDetector(CAMERA, layout)
    with CameraSource(str(path)) as source:
        frames = [source.read() for _ in range(5)]
        assert source.read() is None
    assert [f.capture_t_s for f in frames] == pytest.approx([0.0, 0.05, 0.1, 0.15, 0.2])
    for frame, p in zip(frames, poses):
        m = detector.measure(frame.image, frame.capture_t_s, p.attitude_q_wxyz)
        assert m is not None and np.linalg.norm(m.deck_rel_ned_m - truth(p)) < 0.03
    with pytest.raises(CameraError):
        CameraSource(str(tmp_path / "none.avi"))


def test_poses_from_two_sih_ground_truths():
    """Two HIL_STATE_QUATERNIONs: the carrier 10 m north, 5 m east and 3 m below the vehicle,
    heading east; the deck 0.5 m ahead of the carrier's reference point."""
    from types import SimpleNamespace

    from mission.vision.frames import euler_quaternion
    from sim.camera.render import poses_from_ground_truth, relative_velocity_from_ground_truth

    lat0, lon0 = 47.397742, 8.545594
    north_deg = 10.0 / 6371000.0 * 180 / np.pi
    east_deg = 5.0 / (6371000.0 * np.cos(np.radians(lat0))) * 180 / np.pi
    vehicle = SimpleNamespace(lat=int(lat0 * 1e7), lon=int(lon0 * 1e7), alt=503000, vx=100, vy=0, vz=0,
                              attitude_quaternion=euler_quaternion(0.0, 0.1, 0.0).tolist())
    carrier = SimpleNamespace(lat=int(round((lat0 + north_deg) * 1e7)), lon=int(round((lon0 + east_deg) * 1e7)), alt=500000,
                              vx=300, vy=0, vz=0, attitude_quaternion=euler_quaternion(0.0, 0.0, np.pi / 2).tolist())
    poses = poses_from_ground_truth(vehicle, carrier, deck_offset_m=(0.5, 0.0, 0.0))
    assert np.allclose(poses.deck_ned_m, [10.0, 5.5, 3.0], atol=0.02) and poses.deck_yaw_rad == pytest.approx(np.pi / 2)
    assert np.allclose(relative_velocity_from_ground_truth(vehicle, carrier), [2.0, 0.0, 0.0])
