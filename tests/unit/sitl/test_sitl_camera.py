"""The PX4 SITL camera node (sim/sitl/camera.py): frames rendered from two SIH truths (the
passenger tilted, the rover below it) through the mock's publisher, and the controller's detector
finds in their pixels the deck where the truth has it."""
from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from mission.bus.frames import decode_frame
from mission.config.schema import load_config
from mission.model import vision_detector
from mission.vision.frames import euler_quaternion
from sim.camera.publisher import CameraPublisher
from sim.sitl.camera import CARRIER_MAX_AGE_S, deck_truth
from tests.conftest import CONFIGS

LAT0, LON0 = 47.397742, 8.545594
M_PER_DEG = 6371000.0 * np.pi / 180


class Session:
    def __init__(self) -> None:
        self.payloads: list[bytes] = []

    def declare_publisher(self, key: str, **_: Any) -> Session:
        return self

    def put(self, payload: bytes, attachment: Any = None) -> None:
        self.payloads.append(payload)

    def undeclare(self) -> None:
        pass


def hil(north_m: float, east_m: float, alt_m: float, q: Any, v_cm_s: tuple[int, int, int] = (0, 0, 0)) -> SimpleNamespace:
    lat = LAT0 + north_m / M_PER_DEG
    lon = LON0 + east_m / (M_PER_DEG * np.cos(np.radians(LAT0)))
    return SimpleNamespace(lat=int(round(lat * 1e7)), lon=int(round(lon * 1e7)), alt=int(round(alt_m * 1000)),
                           vx=v_cm_s[0], vy=v_cm_s[1], vz=v_cm_s[2], attitude_quaternion=list(q))


@pytest.mark.parametrize("roll, pitch, yaw", [(0.0, 0.0, 0.0), (0.12, -0.08, 0.7)])
def test_the_detector_finds_the_deck_where_sih_s_truth_has_it(roll: float, pitch: float, yaw: float):
    cfg = load_config(CONFIGS / "px4_sitl_relnav.toml")
    session = Session()
    camera = CameraPublisher(cfg, session, "pair0", seed=0, lockstep=False)  # type: ignore[arg-type]
    vehicle = hil(3.0, -2.0, 490.0, euler_quaternion(roll, pitch, yaw), (120, 0, 0))
    # the rover 0.3 m north and 0.2 m east of the passenger, 2.5 m below; its truth 0.1 s older, driving north at 1.2 m/s
    rover = hil(3.3 - 0.12, -1.8, 487.5, euler_quaternion(0.0, 0.0, 0.2), (120, 0, 0))
    body, deck = deck_truth((10.0, vehicle), (9.9, rover))
    assert deck is not None and np.allclose(deck.position_ned_m, [0.3, 0.2, 2.5], atol=0.01)
    detector = vision_detector(cfg)
    seen = []
    for k in range(40):  # a few dropouts (vision.dropout_probability) aside, frames come
        camera.sample(1.0 + k / cfg.vision.rate_hz, body, deck)
    for payload in session.payloads:
        frame, q = decode_frame(payload)
        if frame.image.size:
            m = detector.measure_corners(detector.corners(frame.image), frame.capture_t_s, q)
            if m is not None:
                seen.append(np.asarray(m.deck_rel_ned_m))
    assert len(seen) >= 30
    assert np.allclose(np.median(seen, axis=0), [0.3, 0.2, 2.5], atol=0.03), np.median(seen, axis=0)


def test_an_old_carrier_truth_is_no_deck():
    q = euler_quaternion(0.0, 0.0, 0.0)
    _, deck = deck_truth((10.0, hil(0, 0, 490, q)), (10.0 - CARRIER_MAX_AGE_S - 0.01, hil(0, 0, 488, q)))
    assert deck is None
