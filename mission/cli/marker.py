"""The marker feed in flight (``mission.feeds = ["marker"]``, entry point ``marsupial.feeds``): the
passenger's downward camera's frames from the bus (:mod:`mission.bus.frames`), the marker detector
and pose of ``[vision]`` on their pixels (:func:`mission.model.vision_detector`), each detection a
:class:`~mission.phases.measurements.RelativePosition` (the deck centre less the vehicle, NED [m])
stamped at capture.

A reading is handed to the mission no earlier than ``vision.latency_s`` after its capture (a real
camera's frame arrives that late anyway; a simulated one, published at capture, then arrives as
late as the real one would). In lockstep (a :class:`~mission.time.clock.LockstepClock`) the feed
also waits, at most :data:`LOCKSTEP_WAIT_WALL_S` of wall time a tick, until the camera's stream
has passed the due time (a frame or a time mark captured at or after it), so every frame is fused
at the same tick whatever the transport's delay (``late_ticks`` counts the ticks it gave up).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from mission.bus.frames import FrameSubscriber
from mission.config.schema import Config
from mission.model import vision_detector
from mission.phases.measurements import Measurement, RelativePosition


LOCKSTEP_WAIT_WALL_S = 1.0  # [s, wall] in lockstep, the longest a tick waits for the camera's stream


class MarkerFeed:
    """A :class:`~mission.interfaces.MeasurementSource` of the marker on the camera's frames."""

    def __init__(self, cfg: Config, session: Any, lockstep: bool = False) -> None:
        self.detector = vision_detector(cfg)
        self.latency_s = cfg.vision.latency_s
        self.frames = FrameSubscriber(session, cfg.zenoh.pair)
        self.pending: list[RelativePosition] = []
        self.detected = self.missed = self.late_ticks = 0
        self.lockstep = lockstep
        self._heard = False  # a lockstep feed waits only once the camera has been heard

    def poll(self, t_s: float) -> list[Measurement]:
        due_s = t_s - self.latency_s
        if self.lockstep:
            self._heard = self._heard or self.frames.newest_t_s > -math.inf
            if self._heard and not self.frames.wait_past(due_s, LOCKSTEP_WAIT_WALL_S):
                self.late_ticks += 1
        for frame, q in self.frames.take():
            m = self.detector.measure(frame.image, frame.capture_t_s, q)
            if m is None:
                self.missed += 1
                continue
            self.detected += 1
            self.pending.append(RelativePosition(capture_t_s=frame.capture_t_s,
                                                 offset_ned_m=np.asarray(m.deck_rel_ned_m, float),
                                                 sigma_m=float(m.sigma_m), marker=int(m.tag_ids[0])))
        due = [m for m in self.pending if m.capture_t_s + self.latency_s <= t_s + 1e-9]
        self.pending = [m for m in self.pending if m.capture_t_s + self.latency_s > t_s + 1e-9]
        return list(due)

    def close(self) -> None:
        self.frames.close()
        self.pending = []


def open_feed(cfg: Config, session: Any, clock: Any) -> MarkerFeed:
    """The opener ``marsupial run`` calls for the feed name ``marker`` (waiting in lockstep)."""
    from mission.time.clock import LockstepClock

    return MarkerFeed(cfg, session, lockstep=isinstance(clock, LockstepClock))
