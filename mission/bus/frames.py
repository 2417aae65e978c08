"""Camera frames over Zenoh (thin I/O): a camera's grey frames, each with its capture time and the
vehicle's attitude then, on ``marsupial/<pair>/passenger/camera`` (:func:`camera_key`).

The passenger's marker feed (``mission.feeds = ["marker"]``, :mod:`mission.cli.marker`) reads
them and runs the detector on the pixels (a passenger of a team of several reads its own camera,
``marsupial/<pair>/passenger/<name>/camera``, as its status is on its own keys); what publishes
them is a camera node beside the autopilot, or in simulation the mock vehicle rendering its
downward camera from the true poses (``mock-vehicle --camera``). One sample a frame: a JSON
header (``t`` the capture time [s] on the mission's clock, ``q`` the attitude body -> NED, w x y
z, ``w`` and ``h`` the size [px]), a zero byte, then the ``h x w`` grey pixels, row by row, one
byte each. A sample of size 0 x 0 is a time mark: no frame at that capture time (dropped, or
nothing in view), so a reader in lockstep knows the stream has passed that time (:meth:`FrameSubscriber.wait_past`).

On a signed bus the camera node signs each sample with its robot's own key (the passenger's:
:meth:`mission.bus.auth.BusAuth.own_verifier` checks it, the attachment as every signed sample's,
:mod:`mission.bus.signing`); a subscriber given a verifier drops, and counts by reason, every
sample that does not verify (unsigned, a bad signature, a replay), time marks included, so no
forged frame reaches the detector and no forged time ends a lockstep wait.
"""
from __future__ import annotations

import json
import logging
import math
import threading
import time
from collections import deque

import numpy as np
import zenoh

from mission.bus.auth import SampleVerifier
from mission.bus.session import declare, keys, undeclare
from mission.bus.wire import WireError
from mission.vision.camera import Frame

log = logging.getLogger(__name__)

MAX_FRAME_BYTES = 4096 * 4096 + 1024  # a frame larger than the schema's largest image is refused


def camera_key(pair: str, passenger: str | None = None) -> str:
    """The camera frames' key of pair ``pair``; ``passenger``: the camera of that passenger of a
    team of several (``team.passengers[].name``), beside its own status key."""
    own = keys(pair, passenger).passenger_state.rsplit("/", 1)[0]
    return f"{own}/camera"


def encode_frame(frame: Frame, attitude_q_wxyz: np.ndarray) -> bytes:
    """One sample: ``frame`` (uint8 H x W) and the attitude at its capture (module docstring)."""
    image = np.ascontiguousarray(frame.image, dtype=np.uint8)
    header = {"t": float(frame.capture_t_s), "q": [float(v) for v in attitude_q_wxyz], "w": int(image.shape[1]),
              "h": int(image.shape[0])}
    return json.dumps(header).encode() + b"\0" + image.tobytes()


def encode_mark(capture_t_s: float) -> bytes:
    """A time mark: no frame captured at ``capture_t_s`` [s] (module docstring)."""
    return json.dumps({"t": float(capture_t_s), "q": [1.0, 0.0, 0.0, 0.0], "w": 0, "h": 0}).encode() + b"\0"


def decode_frame(payload: bytes) -> tuple[Frame, np.ndarray]:
    """The frame and attitude of a sample; ValueError if it is not one."""
    if len(payload) > MAX_FRAME_BYTES:
        raise ValueError(f"{len(payload)} bytes > {MAX_FRAME_BYTES}")
    head, sep, pixels = payload.partition(b"\0")
    if not sep:
        raise ValueError("no header")
    h = json.loads(head)
    width, height, q = int(h["w"]), int(h["h"]), np.asarray(h["q"], dtype=float)
    if width < 0 or height < 0 or len(pixels) != width * height or q.shape != (4,) or not np.isfinite(q).all() or not np.isfinite(h["t"]):
        raise ValueError(f"bad frame: {width}x{height}, {len(pixels)} bytes, q {q}")
    return Frame(np.frombuffer(pixels, dtype=np.uint8).reshape(height, width), float(h["t"])), q


class FrameSubscriber:
    """The newest frames of pair ``pair``'s camera (``passenger``: of that team passenger's,
    :func:`camera_key`), at most ``depth`` kept (older ones dropped, counted); :meth:`take` returns
    and forgets them, oldest first."""

    def __init__(self, session: zenoh.Session, pair: str, depth: int = 8, verifier: SampleVerifier | None = None,
                 passenger: str | None = None) -> None:
        self.key = camera_key(pair, passenger)
        self._verifier = verifier
        self.refused: dict[str, int] = {}  # samples that did not verify, by reason (unsigned, signature, replay)
        self._lock = threading.Lock()
        self._arrived = threading.Condition(self._lock)
        self.newest_t_s = -math.inf  # [s] the newest capture time heard (frames arrive in capture order)
        self._frames: deque[tuple[Frame, np.ndarray]] = deque(maxlen=depth)
        self.received = self.malformed = self.overflowed = 0
        self._sub = declare(f"subscriber on {self.key}", lambda: session.declare_subscriber(self.key, self._on_sample))

    def _on_sample(self, sample: zenoh.Sample) -> None:
        payload = sample.payload.to_bytes()
        if self._verifier is not None:
            try:
                self._verifier.verify(sample, payload)
            except WireError as exc:
                with self._lock:
                    self.refused[exc.reason] = self.refused.get(exc.reason, 0) + 1
                    first = sum(self.refused.values()) == 1
                (log.warning if first else log.debug)("refused a camera sample on %s: %s", self.key, exc)
                return
        try:
            got = decode_frame(payload)
        except (ValueError, KeyError, TypeError) as exc:
            with self._lock:
                self.malformed += 1
                first = self.malformed == 1
            (log.warning if first else log.debug)("dropped a camera frame on %s: %s", self.key, exc)
            return
        with self._lock:
            self.received += 1
            self.newest_t_s = max(self.newest_t_s, got[0].capture_t_s)
            if got[0].image.size:
                if len(self._frames) == self._frames.maxlen:
                    self.overflowed += 1
                self._frames.append(got)
            self._arrived.notify_all()

    def wait_past(self, t_s: float, timeout_wall_s: float) -> bool:
        """Wait (at most ``timeout_wall_s`` wall seconds) until a frame or time mark captured at or
        after ``t_s`` [s] has arrived: every frame captured before it has then arrived too (one
        publisher, in order). True if it has."""
        deadline = time.monotonic() + timeout_wall_s
        with self._lock:
            while self.newest_t_s < t_s:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._arrived.wait(left)
            return True

    def take(self) -> list[tuple[Frame, np.ndarray]]:
        with self._lock:
            out = list(self._frames)
            self._frames.clear()
        return out

    def close(self) -> None:
        undeclare(self._sub)
        self._sub = None
