"""The passenger camera's frames, read off the bus by the marker feed, land in ``flight.mcap`` as a
Foxglove user reads them: ``foxglove.CompressedImage`` (JPEG), ``foxglove.CameraCalibration``
(the detector's pinhole), ``foxglove.ImageAnnotations`` (the tag's corners) and the camera's mount
transform, decoded here with the ``mcap`` and ``mcap-protobuf-support`` readers against the
schemas foxglove-sdk wrote (foxglove-sdk 0.30.3). Real Zenoh sessions on loopback."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from mission.bus.frames import camera_key, encode_frame
from mission.cli.marker import MarkerFeed
from mission.config.schema import load_config, with_overrides
from mission.flightdata.mission_log import MissionLog
from mission.flightdata.topics import CAMERA_CHANNELS, camera_frame, frame, topics
from mission.model import vision_detector
from mission.vision.camera import Frame
from mission.vision.frames import quaternion_matrix
from mission.vision.measurement import MarkerPose
from sim.camera.render import render
from tests.conftest import CONFIGS
from tests.support.zenoh_util import peer_pair, wait_for

pytestmark = pytest.mark.timeout(60)

INFO = {"target_ned_m": [20.0, 0.0, -5.0], "obstacles": [], "bc_m": 8.0, "carrier_start_ned_m": [0.0, 0.0, 0.0],
        "dock_offset_ned_m": [0, 0, -1.5], "dock_tolerance_m": 0.5, "arrival_radius_m": 0.5, "pair": "pairC"}
FRAMES = 30  # at 30 Hz of capture time: one second
LEVEL_Q = np.array([1.0, 0.0, 0.0, 0.0])  # the vehicle level, heading north


def _decoded(path):
    """Every message of ``path`` as (topic, schema name, log time [ns], decoded protobuf)."""
    decoder = DecoderFactory()
    out = []
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if schema.encoding == "protobuf":
                decode = decoder.decoder_for(channel.message_encoding, schema)
                assert decode is not None, schema.name
                out.append((channel.topic, schema.name, message.log_time, decode(message.data)))
            else:
                out.append((channel.topic, schema.name, message.log_time, json.loads(message.data)))
    return out


def test_the_feeds_frames_reach_the_mcap_at_the_log_rate_with_the_tag_drawn(tmp_path) -> None:
    # an 80 deg camera: the small tag 2 m away is 19 px wide (at relnav.toml's 90 deg, 16 px: not found)
    cfg = with_overrides(load_config(CONFIGS / "relnav.toml"), {"zenoh.pair": "pairC", "vision.log_rate_hz": 10.0,
                                                               "vision.hfov_deg": 80.0})
    detector = vision_detector(cfg)
    camera = detector.camera
    # the vehicle level heading north, the deck (aligned with NED) 2 m below it and 0.2 m east
    cam_ned = camera.mount.rotation_body_cam.T
    image = render(camera, detector.layout, MarkerPose(cam_ned, cam_ned @ np.array([0.0, 0.2, 2.0])))
    assert (image < 60).any(), "the tag was not rendered into the frame"
    log = MissionLog(tmp_path / "flight.mcap", INFO, pair="pairC", clock={"clock": "mission"})
    try:
        with peer_pair() as (a, b):
            feed = MarkerFeed(cfg, b, lockstep=False)
            feed.show_frames_to(log)
            pub = a.declare_publisher(camera_key("pairC"))
            try:
                wait_for(lambda: pub.matching_status.matching, 10.0, "the feed's subscriber")
                readings = 0
                for k in range(FRAMES):
                    capture = 5.0 + k / 30.0
                    pub.put(encode_frame(Frame(image, capture), LEVEL_Q))
                    wait_for(lambda: feed.frames.received > k, 10.0, f"frame {k}")
                    readings += len(feed.poll(capture + 1.0))
            finally:
                pub.undeclare()
                feed.close()
    finally:
        log.close({}, {})
    assert feed.detected == FRAMES and readings == FRAMES, (feed.detected, feed.missed)
    assert feed.logged == 10, feed.logged  # one second of frames at vision.log_rate_hz = 10
    names = topics("pairC", CAMERA_CHANNELS)
    got = [m for m in _decoded(tmp_path / "flight.mcap") if m[0] in names.values()]
    by_topic = {key: [m for m in got if m[0] == topic] for key, topic in names.items()}
    assert {k: len(v) for k, v in by_topic.items()} == {"image": 10, "calibration": 10, "detections": 10, "mount_tf": 1}
    assert {m[1] for m in got} == {schema for _, _, schema in CAMERA_CHANNELS}

    first = by_topic["image"][0][3]
    assert first.format == "jpeg" and first.frame_id == camera_frame("pairC")
    assert first.timestamp.seconds == 5 and first.timestamp.nanos == 0  # the capture time, not the arrival
    assert by_topic["image"][0][2] == 6_000_000_000  # logged when the mission polled it
    seen = cv2.imdecode(np.frombuffer(first.data, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert seen.shape == image.shape and float(np.abs(seen.astype(float) - image).mean()) < 2.0

    calibration = by_topic["calibration"][0][3]
    assert (calibration.width, calibration.height) == (camera.width, camera.height)
    assert np.allclose(calibration.K, camera.matrix.ravel()) and calibration.distortion_model == "plumb_bob"
    assert np.allclose(np.reshape(calibration.P, (3, 4))[:, :3], camera.matrix)

    found = detector.corners(image)
    annotations = by_topic["detections"][0][3]
    assert len(found.ids) == 2 == len(annotations.points)  # relnav.toml's bundle: the big tag and the small one
    assert [t.text for t in annotations.texts] == [f"tag {int(i)}" for i in found.ids]
    for outline, corners in zip(annotations.points, found.corners):
        drawn = np.array([[p.x, p.y] for p in outline.points])
        assert np.allclose(drawn, corners + 0.5, atol=1e-4)  # Foxglove's origin: the top-left pixel's corner

    mount = by_topic["mount_tf"][0][3]
    assert (mount.parent_frame_id, mount.child_frame_id) == (frame("pairC", "passenger"), camera_frame("pairC"))
    r = mount.rotation
    assert np.allclose(quaternion_matrix(np.array([r.w, r.x, r.y, r.z])), camera.mount.rotation_body_cam)


def test_on_a_signed_bus_only_the_passengers_own_camera_is_read(tmp_path) -> None:
    """One key per robot: frames signed with the passenger's own key are read; unsigned ones and
    ones signed with another robot's key (the carrier's) are refused and counted, and a forged
    time mark does not end a lockstep wait (it would let the mission fuse before the real frame)."""
    from mission.bus.auth import SampleSigner
    from mission.config.keys import read_private_key_file, write_key_pair
    from sim.vehicle.cli import camera_signer

    keys = {robot: (tmp_path / f"{robot}.key", tmp_path / f"{robot}.pub") for robot in ("passenger", "carrier")}
    for private, public in keys.values():
        write_key_pair(private, public)
    cfg = with_overrides(load_config(CONFIGS / "relnav.toml"), {
        "zenoh.pair": "pairS", "zenoh.private_key_file": str(keys["passenger"][0]),
        "zenoh.peer_public_key_file": str(keys["carrier"][1])})
    detector = vision_detector(cfg)
    cam_ned = detector.camera.mount.rotation_body_cam.T
    image = render(detector.camera, detector.layout, MarkerPose(cam_ned, cam_ned @ np.array([0.0, 0.2, 2.0])))
    own = camera_signer(keys["passenger"][0], None, "pairS", True)  # what mock-vehicle --zenoh-private-key signs with
    assert own is not None
    other = SampleSigner(read_private_key_file(keys["carrier"][0], "test"))
    key = camera_key("pairS")
    with peer_pair() as (a, b):
        feed = MarkerFeed(cfg, b, lockstep=True)
        pub = a.declare_publisher(key)
        try:
            wait_for(lambda: pub.matching_status.matching, 10.0, "the feed's subscriber")
            sent = 0

            def put(t: float, signer, mark: bool = False) -> None:
                nonlocal sent
                payload = json.dumps({"t": t, "q": [1, 0, 0, 0], "w": 0, "h": 0}).encode() + b"\0" if mark else encode_frame(
                    Frame(image, t), LEVEL_Q)
                pub.put(payload, attachment=None if signer is None else signer.attachment(key, payload))
                sent += 1
                wait_for(lambda: feed.frames.received + sum(feed.frames.refused.values()) >= sent, 10.0, f"sample {sent}")

            put(1.0, own)
            put(1.1, None)  # unsigned
            put(1.2, other)  # the carrier's key: authentic, but not the passenger's camera
            put(9.0, None, mark=True)  # a forged time mark far ahead
            assert not feed.frames.wait_past(5.0, 0.05), "a forged time mark ended the lockstep wait"
            readings = feed.poll(2.0)
            put(9.0, own, mark=True)
            assert feed.frames.wait_past(5.0, 0.05)
        finally:
            pub.undeclare()
            feed.close()
    assert [m.capture_t_s for m in readings] == [1.0]
    c = feed.counters
    assert c["signed"] and c["received"] == 2 and c["refused"] == {"unsigned": 2, "signature": 1}, c
    assert c["detected"] == 1 and c["missed"] == 0, c


def test_a_lockstep_feed_whose_camera_goes_silent_waits_once_not_every_tick(monkeypatch) -> None:
    """In lockstep a tick waits (wall time, bounded) for the camera's stream to pass its due time;
    a camera gone silent costs one such wait, then none until the stream moves again."""
    import mission.cli.marker as marker
    from mission.bus.frames import encode_mark
    monkeypatch.setattr(marker, "LOCKSTEP_WAIT_WALL_S", 0.2)
    cfg = with_overrides(load_config(CONFIGS / "relnav.toml"), {"zenoh.pair": "pairS"})
    with peer_pair() as (a, b):
        feed = MarkerFeed(cfg, b, lockstep=True)
        pub = a.declare_publisher(camera_key("pairS"))
        try:
            wait_for(lambda: pub.matching_status.matching, 10.0, "the feed's subscriber")
            pub.put(encode_mark(1.0))
            wait_for(lambda: feed.frames.received > 0 or feed.frames.newest_t_s >= 1.0, 10.0, "the first mark")
            feed.poll(1.0 + feed.latency_s)  # the stream has passed it: no wait
            assert feed.late_ticks == 0
            for k in range(5):  # silent from here: the first tick waits and gives up, the rest do not wait
                feed.poll(2.0 + k / 50.0 + feed.latency_s)
            assert feed.late_ticks == 1
            pub.put(encode_mark(3.0))  # it moves again: a tick past it waits for it once more
            wait_for(lambda: feed.frames.newest_t_s >= 3.0, 10.0, "the second mark")
            feed.poll(3.0 + feed.latency_s)
            assert feed.late_ticks == 1
            feed.poll(4.0 + feed.latency_s)
            assert feed.late_ticks == 2
        finally:
            pub.undeclare()
            feed.close()
