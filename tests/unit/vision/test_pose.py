"""The detector on rendered frames: the deck's position from the vehicle against the truth, per
height; the bundle's small tag in the last half metre; no measurement rather than a wrong one."""
from __future__ import annotations

import numpy as np
import pytest

from mission.vision.detect import MarkerDetector, predicted_roi, schema_settings
from mission.vision.frames import euler_quaternion, quaternion_matrix
from mission.vision.layout import MarkerLayout
from sim.camera.render import render, true_marker_pose
from sim.camera.sensor import Sensor, sensor_model
from sim.camera.simulated import SimulatedCamera
from tests.unit.vision.scenes import CAMERA, aimed, random_attitudes, truth

NO_DROPS = sensor_model(noise_sigma=2.0, dropout_probability=0.0)

# The bound on |measured - true| [m] per camera height [m], tilts up to 20 deg, any yaw, the
# optical axis within 10 % of the height of the deck centre; 2 grey levels of noise. Measured over
# 40 poses a height (docs/vision.md): max 0.2 / 0.8 / 4.8 / 31 cm at 1 / 2 / 4 / 8 m for the
# single 0.5 m tag, so these leave room for other seeds.
BOUNDS_M = {1.0: 0.02, 2.0: 0.03, 4.0: 0.10, 8.0: 0.40}


@pytest.mark.parametrize("height_m", sorted(BOUNDS_M))
def test_single_tag_position_error_per_height(height_m):
    layout = MarkerLayout.single(0.5)
    detector = MarkerDetector(CAMERA, layout)
    camera = SimulatedCamera(CAMERA, layout, Sensor(NO_DROPS, seed=int(height_m * 10)))
    rng = np.random.default_rng(7)
    errors = []
    for roll, pitch, yaw in random_attitudes(int(height_m * 100), 8, 20.0):
        poses = aimed(CAMERA, height_m, roll, pitch, yaw, rng.uniform(-0.1, 0.1, 2) * height_m, rng.uniform(-3, 3))
        frame = camera.capture(poses, 12.5)
        m = detector.measure(frame.image, frame.capture_t_s, poses.attitude_q_wxyz)
        assert m is not None, (roll, pitch, yaw)
        assert m.capture_t_s == 12.5 and m.tag_ids == (0,)
        errors.append(np.linalg.norm(m.deck_rel_ned_m - truth(poses)))
    assert max(errors) <= BOUNDS_M[height_m], errors


def test_the_bound_can_fail():
    """A camera model 5 % off in focal length (a wrong calibration) breaks the 2 m bound."""
    layout = MarkerLayout.single(0.5)
    wrong = type(CAMERA)(CAMERA.matrix * np.array([[1.05], [1.05], [1.0]]), CAMERA.distortion, 640, 480, CAMERA.mount)
    poses = aimed(CAMERA, 2.0, 5.0, -5.0, 40.0)
    frame = SimulatedCamera(CAMERA, layout, Sensor(NO_DROPS)).capture(poses, 0.0)
    m = MarkerDetector(wrong, layout).measure(frame.image, 0.0, poses.attitude_q_wxyz)
    assert m is not None and np.linalg.norm(m.deck_rel_ned_m - truth(poses)) > BOUNDS_M[2.0]


def test_the_measurement_frames_agree():
    """Body and NED vectors differ by the attitude used; the deck's yaw and the covariance's scale
    come out right."""
    layout = MarkerLayout.single(0.5)
    poses = aimed(CAMERA, 2.0, 10.0, -15.0, 120.0, (0.1, -0.2), deck_yaw_rad=-1.0)
    frame = SimulatedCamera(CAMERA, layout, Sensor(NO_DROPS, seed=3)).capture(poses, 0.0)
    m = MarkerDetector(CAMERA, layout).measure(frame.image, 0.0, poses.attitude_q_wxyz)
    assert m is not None
    assert np.allclose(quaternion_matrix(m.attitude_q_wxyz) @ m.deck_body_frd_m, m.deck_rel_ned_m)
    assert m.deck_yaw_ned_rad == pytest.approx(-1.0, abs=np.radians(2))
    assert 1e-4 < m.sigma_m < 0.03 and m.reprojection_error_px < 0.5
    assert m.distance_m == pytest.approx(np.linalg.norm(truth(poses)), abs=0.02)
    assert np.allclose(m.covariance_ned_m2, m.covariance_ned_m2.T)


def test_the_bundle_sees_its_small_tag_in_the_last_half_metre():
    """At 0.3 m the big tag overflows the image; the bundle's small tag at the deck centre still
    gives a pose, within 1 cm. The single big tag gives none there."""
    bundle = MarkerLayout.bundle()
    detector = MarkerDetector(CAMERA, bundle)
    camera = SimulatedCamera(CAMERA, bundle, Sensor(NO_DROPS, seed=4))
    for roll, pitch, yaw in random_attitudes(11, 6, 8.0):
        poses = aimed(CAMERA, 0.3, roll, pitch, yaw)
        frame = camera.capture(poses, 0.0)
        m = detector.measure(frame.image, 0.0, poses.attitude_q_wxyz)
        assert m is not None and 1 in m.tag_ids
        assert np.linalg.norm(m.deck_rel_ned_m - truth(poses)) < 0.01
        single = MarkerLayout.single(0.5)
        frame = SimulatedCamera(CAMERA, single, Sensor(NO_DROPS)).capture(poses, 0.0)
        assert MarkerDetector(CAMERA, single).measure(frame.image, 0.0, poses.attitude_q_wxyz) is None


def test_the_bundle_uses_both_tags_when_both_are_seen():
    bundle = MarkerLayout.bundle()
    poses = aimed(CAMERA, 1.5, 0.0, 0.0, 0.0, (0.2, 0.0))
    frame = SimulatedCamera(CAMERA, bundle, Sensor(NO_DROPS, seed=5)).capture(poses, 0.0)
    m = MarkerDetector(CAMERA, bundle).measure(frame.image, 0.0, poses.attitude_q_wxyz)
    assert m is not None and m.tag_ids == (0, 1)
    assert np.linalg.norm(m.deck_rel_ned_m - truth(poses)) < 0.02


def test_a_dropped_frame_and_an_occluded_tag_give_nothing_never_a_wrong_pose():
    layout = MarkerLayout.single(0.5)
    poses = aimed(CAMERA, 2.0, 5.0, 5.0, 30.0)
    assert SimulatedCamera(CAMERA, layout, Sensor(sensor_model(dropout_probability=1.0))).capture(poses, 0.0) is None
    detector = MarkerDetector(CAMERA, layout)
    ideal = render(CAMERA, layout, true_marker_pose(CAMERA, poses))
    rng = np.random.default_rng(9)
    seen = 0
    for _ in range(30):  # a random grey block (a leg, a shadow) over part of the image
        image = ideal.copy()
        x, y = rng.integers(150, 450), rng.integers(100, 350)
        w, h = rng.integers(20, 150, 2)
        image[y:y + h, x:x + w] = rng.integers(0, 255)
        m = detector.measure(image, 0.0, poses.attitude_q_wxyz)
        if m is not None:
            seen += 1
            assert np.linalg.norm(m.deck_rel_ned_m - truth(poses)) < 0.03
    assert seen < 30  # some blocks hid the tag: the check saw occlusions
    ideal[180:300, 280:360] = 110  # the tag's middle covered: nothing
    assert detector.measure(ideal, 0.0, poses.attitude_q_wxyz) is None


def test_a_pose_that_disagrees_with_the_attitude_is_rejected():
    """Told the vehicle is level while it is rolled 40 deg, the deck would be tilted 40 deg: the
    tilt gate rejects both of IPPE's solutions."""
    layout = MarkerLayout.single(0.5)
    poses = aimed(CAMERA, 2.0, 40.0, 0.0, 0.0)
    frame = SimulatedCamera(CAMERA, layout, Sensor(NO_DROPS)).capture(poses, 0.0)
    detector = MarkerDetector(CAMERA, layout)
    assert detector.measure(frame.image, 0.0, poses.attitude_q_wxyz) is not None
    assert detector.measure(frame.image, 0.0, euler_quaternion(0.0, 0.0, 0.0)) is None


def test_far_ambiguous_tags_take_the_level_solution():
    """At 6-10 m IPPE's two solutions reproject almost alike and the lower error is often the
    flipped one (a deck tilted 10-30 deg); preferring the more level of two ambiguous solutions keeps
the deck's normal within 10 deg of the truth more often."""
    layout = MarkerLayout.single(0.5)
    detector = MarkerDetector(CAMERA, layout)
    plain = MarkerDetector(CAMERA, layout, schema_settings(ambiguity_ratio=1.0))  # lower error wins
    camera = SimulatedCamera(CAMERA, layout, Sensor(sensor_model(noise_sigma=4.0, dropout_probability=0.0), seed=6))
    rng = np.random.default_rng(14)
    tilts: dict[str, list[float]] = {"gated": [], "plain": []}
    for i, (roll, pitch, yaw) in enumerate(random_attitudes(13, 40, 20.0)):
        poses = aimed(CAMERA, 6.0 + i % 3 * 2, roll, pitch, yaw, rng.uniform(-0.3, 0.3, 2) * 6.0)
        frame = camera.capture(poses, 0.0)
        rotation_ned_cam = quaternion_matrix(poses.attitude_q_wxyz) @ CAMERA.mount.rotation_body_cam
        for d, name in ((detector, "gated"), (plain, "plain")):
            m = d.measure(frame.image, 0.0, poses.attitude_q_wxyz)
            if m is None:
                continue
            tilts[name].append(np.degrees(np.arccos(np.clip((rotation_ned_cam @ m.marker.rotation_cam_deck)[2, 2], -1, 1))))
    flipped = {name: sum(t > 10.0 for t in values) for name, values in tilts.items()}
    # seeded (sensor seed 6): 3 of 40 gated poses against 7 when the lower error wins. Over sensor seeds 0-7
    # the gated flipped 2-3 and the plain 4-8, at least 2 more (with the read noise drawn afresh each frame
    # as with windows of a bank): a bound at this seed's own count would hold on its luck alone
    assert len(tilts["gated"]) >= 35 and flipped["gated"] <= 3 and flipped["plain"] >= flipped["gated"] + 2, flipped


def test_a_region_of_interest_finds_the_same_pose():
    layout = MarkerLayout.single(0.5)
    poses = aimed(CAMERA, 4.0, 10.0, 0.0, 60.0, (0.5, 0.3))
    frame = SimulatedCamera(CAMERA, layout, Sensor(NO_DROPS, seed=8)).capture(poses, 0.0)
    detector = MarkerDetector(CAMERA, layout)
    full = detector.measure(frame.image, 0.0, poses.attitude_q_wxyz)
    assert full is not None
    roi = predicted_roi(CAMERA, layout, full.marker)
    assert (roi[2] - roi[0]) * (roi[3] - roi[1]) < 640 * 480 / 4
    cropped = detector.measure(frame.image, 0.0, poses.attitude_q_wxyz, roi=roi)
    assert cropped is not None and np.allclose(cropped.deck_rel_ned_m, full.deck_rel_ned_m, atol=1e-6)
