"""Camera frames over Zenoh (thin I/O): a camera's grey frames, each with its capture time and the
vehicle's attitude then, on ``marsupial/<pair>/passenger/camera`` (:func:`camera_key`).

The passenger's marker feed (``mission.feeds = ["marker"]``, :mod:`mission.cli.marker`) reads
them and runs the detector on the pixels; what publishes them is a camera node beside the
autopilot, or in simulation the mock vehicle rendering its downward camera from the true poses
(``mock-vehicle --camera``). One sample a frame: a JSON header (``t`` the capture time [s] on the
mission's clock, ``q`` the attitude body -> NED, w x y z, ``w`` and ``h`` the size [px]), a zero
byte, then the ``h x w`` grey pixels, row by row, one byte each.
"""
from __future__ import annotations

import json
import logging
import threading
from collections import deque

import numpy as np
import zenoh

from mission.bus.session import declare, keys, undeclare
from mission.vision.camera import Frame

log = logging.getLogger(__name__)

MAX_FRAME_BYTES = 4096 * 4096 + 1024  # a frame larger than the schema's largest image is refused


def camera_key(pair: str) -> str:
    """The camera frames' key of pair ``pair``."""
    root = keys(pair).carrier_state.rsplit("/", 2)[0]
    return f"{root}/passenger/camera"


def encode_frame(frame: Frame, attitude_q_wxyz: np.ndarray) -> bytes:
    """One sample: ``frame`` (uint8 H x W) and the attitude at its capture (module docstring)."""
    image = np.ascontiguousarray(frame.image, dtype=np.uint8)
    header = {"t": float(frame.capture_t_s), "q": [float(v) for v in attitude_q_wxyz], "w": int(image.shape[1]),
              "h": int(image.shape[0])}
    return json.dumps(header).encode() + b"\0" + image.tobytes()


def decode_frame(payload: bytes) -> tuple[Frame, np.ndarray]:
    """The frame and attitude of a sample; ValueError if it is not one."""
    if len(payload) > MAX_FRAME_BYTES:
        raise ValueError(f"{len(payload)} bytes > {MAX_FRAME_BYTES}")
    head, sep, pixels = payload.partition(b"\0")
    if not sep:
        raise ValueError("no header")
    h = json.loads(head)
    width, height, q = int(h["w"]), int(h["h"]), np.asarray(h["q"], dtype=float)
    if len(pixels) != width * height or q.shape != (4,) or not np.isfinite(q).all() or not np.isfinite(h["t"]):
        raise ValueError(f"bad frame: {width}x{height}, {len(pixels)} bytes, q {q}")
    return Frame(np.frombuffer(pixels, dtype=np.uint8).reshape(height, width), float(h["t"])), q


class FrameSubscriber:
    """The newest frames of pair ``pair``'s camera, at most ``depth`` kept (older ones dropped,
    counted); :meth:`take` returns and forgets them, oldest first."""

    def __init__(self, session: zenoh.Session, pair: str, depth: int = 8) -> None:
        self.key = camera_key(pair)
        self._lock = threading.Lock()
        self._frames: deque[tuple[Frame, np.ndarray]] = deque(maxlen=depth)
        self.received = self.malformed = self.overflowed = 0
        self._sub = declare(f"subscriber on {self.key}", lambda: session.declare_subscriber(self.key, self._on_sample))

    def _on_sample(self, sample: zenoh.Sample) -> None:
        try:
            got = decode_frame(sample.payload.to_bytes())
        except (ValueError, KeyError, TypeError) as exc:
            with self._lock:
                self.malformed += 1
                first = self.malformed == 1
            (log.warning if first else log.debug)("dropped a camera frame on %s: %s", self.key, exc)
            return
        with self._lock:
            self.received += 1
            if len(self._frames) == self._frames.maxlen:
                self.overflowed += 1
            self._frames.append(got)

    def take(self) -> list[tuple[Frame, np.ndarray]]:
        with self._lock:
            out = list(self._frames)
            self._frames.clear()
        return out

    def close(self) -> None:
        undeclare(self._sub)
        self._sub = None
