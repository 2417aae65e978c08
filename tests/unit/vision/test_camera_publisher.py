"""The mock vehicle's camera publisher (sim/camera/publisher.py) captures on the simulated clock's
grid ``k / vision.rate_hz`` from t = 0, whenever the deck first became known: two relnav demos whose
carrier truth first reached the mock's deck at 0.075 s and at 0.14 s captured every later frame at
different times (the grid was anchored at the first capture), and their records parted at t = 3.6 s
(docs/relnav.md, "The lockstep demo")."""
from __future__ import annotations

from typing import Any

import numpy as np

from mission.bus.frames import decode_frame
from mission.config.schema import load_config, with_overrides
from sim.camera.publisher import BodyTruth, CameraPublisher, DeckTruth
from tests.conftest import CONFIGS

PASS_S = 0.02  # the vehicle's passes in the relnav demo: its 50 Hz streams and barriers [s]


class Publisher:
    def __init__(self) -> None:
        self.payloads: list[bytes] = []

    def put(self, payload: bytes, attachment: Any = None) -> None:
        self.payloads.append(payload)

    def undeclare(self) -> None:
        pass


class Session:
    def __init__(self) -> None:
        self.publisher = Publisher()

    def declare_publisher(self, key: str, **_: Any) -> Publisher:
        return self.publisher


def captures(deck_known_s: float, until_s: float = 0.5) -> list[tuple[float, int]]:
    """(capture time [s], frame width [px]: 0 for a time mark) of a camera 3 m over the deck, the
    deck unknown before ``deck_known_s`` [s], sampled at every pass."""
    # no dropouts: a dropped frame is a time mark too, and whether one falls in these 16 slots is the seed's luck
    cfg = with_overrides(load_config(CONFIGS / "relnav.toml"), {"vision.dropout_probability": 0.0})
    session = Session()
    camera = CameraPublisher(cfg, session, "pair0", seed=0, lockstep=True)  # type: ignore[arg-type]
    body = BodyTruth.level(np.array([0.0, 0.0, -3.0]), 0.0, np.zeros(3))
    for k in range(1, round(until_s / PASS_S) + 1):
        t = k * PASS_S
        if t < deck_known_s - 1e-9:
            camera.sample(t, body, None)
        else:
            camera.sample(t, body, DeckTruth(np.zeros(3), np.zeros(3), 0.0))
    out = []
    for payload in session.publisher.payloads:
        frame, _ = decode_frame(payload)
        out.append((round(frame.capture_t_s, 9), frame.image.shape[1]))
    return out


def test_the_capture_times_are_the_grid_s_whenever_the_deck_became_known():
    early, late = captures(0.075), captures(0.14)
    times = [t for t, _ in early]
    assert times == [t for t, _ in late]  # before: the grid took its phase from the first capture
    # the first pass at or after each slot k / 30 s (the first pass is at 0.02 s)
    rate = load_config(CONFIGS / "relnav.toml").vision.rate_hz
    slots = np.arange(0, 0.5 + 1e-9, 1 / rate)
    expected = [round(float(max(np.ceil(s / PASS_S - 1e-6), 1) * PASS_S), 9) for s in slots]
    assert times == expected == [0.02, 0.04, 0.08, 0.1, 0.14, 0.18, 0.2, 0.24, 0.28, 0.3, 0.34, 0.38, 0.4, 0.44,
                                 0.48, 0.5], (times, expected)
    # while the deck is unknown each slot is a time mark; once known, the deck 3 m below is in view
    assert [w for t, w in early if t < 0.075] == [0, 0] and all(w > 0 for t, w in early if t >= 0.075)
    assert [w for t, w in late if t < 0.14] == [0] * 4 and all(w > 0 for t, w in late if t >= 0.14)
