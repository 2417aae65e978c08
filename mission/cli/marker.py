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

On a signed bus (``zenoh.private_key_file`` or ``zenoh.signing_key_file``) only frames and time
marks signed with the passenger's own key are read (:mod:`mission.bus.frames`); :attr:`MarkerFeed.counters`
go to ``summary.json``'s ``feeds``.

Shown to a :class:`~mission.interfaces.CameraSink` (the flight log), it hands over at most
``vision.log_rate_hz`` of its frames a second (by capture time), each with the tags it found in
it (``logged`` counts them).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from mission.bus.auth import bus_auth
from mission.bus.frames import FrameSubscriber
from mission.config.schema import Config
from mission.interfaces import CameraSink
from mission.model import vision_detector
from mission.phases.measurements import Measurement, RelativePosition
from mission.time.rate import RateGate
from mission.vision.camera import SeenFrame


LOCKSTEP_WAIT_WALL_S = 5.0  # [s, wall] in lockstep, the longest a tick waits for the camera's stream (its
# publisher blocks rather than drop in lockstep, so a wait runs out only on a loaded machine or a lost route;
# the tick is this process's own work, which the vehicle waits for up to its 10 s watchdog)


class MarkerFeed:
    """A :class:`~mission.interfaces.MeasurementSource` of the marker on the camera's frames."""

    def __init__(self, cfg: Config, session: Any, lockstep: bool = False, passenger: str | None = None) -> None:
        self.detector = vision_detector(cfg)
        self.latency_s = cfg.vision.latency_s
        auth = bus_auth(cfg.zenoh)
        self.signed = auth is not None
        self.frames = FrameSubscriber(session, cfg.zenoh.pair, verifier=None if auth is None else auth.own_verifier(),
                                      passenger=passenger)
        self.pending: list[RelativePosition] = []
        self.detected = self.missed = self.late_ticks = 0
        self.lockstep = lockstep
        self._heard = False  # a lockstep feed waits only once the camera has been heard
        self._stalled_at_s: float | None = None  # the stream's newest time when a lockstep wait last ran out
        self._log_gate = RateGate(cfg.vision.log_rate_hz)  # on the frames' capture times
        self._sinks: list[CameraSink] = []
        self.logged = 0

    @property
    def counters(self) -> dict[str, Any]:
        """What the feed read and what it dropped: samples received (frames and time marks),
        refused by reason (they did not verify), malformed, overflowed (not read in time); frames
        whose marker was measured (``detected``) or not (``missed``); lockstep ticks that gave up
        waiting (``late_ticks``); frames handed to the flight log (``logged``)."""
        f = self.frames
        return {"signed": self.signed, "received": f.received, "refused": dict(f.refused), "malformed": f.malformed,
                "overflowed": f.overflowed, "detected": self.detected, "missed": self.missed,
                "late_ticks": self.late_ticks, "logged": self.logged}

    def show_frames_to(self, sink: CameraSink) -> None:
        """Hand ``vision.log_rate_hz`` of the frames a second to ``sink`` as well (module docstring)."""
        self._sinks.append(sink)

    def poll(self, t_s: float) -> list[Measurement]:
        due_s = t_s - self.latency_s
        if self.lockstep:
            newest_s = self.frames.newest_t_s
            self._heard = self._heard or newest_s > -math.inf
            # a stream given up on is not waited for again until it has moved on (a camera gone
            # silent costs one wait, not one a tick)
            if self._heard and newest_s != self._stalled_at_s and not self.frames.wait_past(due_s, LOCKSTEP_WAIT_WALL_S):
                self.late_ticks += 1
                self._stalled_at_s = self.frames.newest_t_s
        for frame, q in self.frames.take():
            found = self.detector.corners(frame.image)
            m = self.detector.measure_corners(found, frame.capture_t_s, q)
            if self._sinks and self._log_gate.due(frame.capture_t_s):
                self._show(t_s, SeenFrame(frame.image, frame.capture_t_s, self.detector.camera, found.ids, found.corners,
                                          m is not None))
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

    def _show(self, t_s: float, seen: SeenFrame) -> None:
        self.logged += 1
        for sink in self._sinks:
            sink.camera(t_s, seen)

    def close(self) -> None:
        self.frames.close()
        self.pending = []


def open_feed(cfg: Config, session: Any, clock: Any, link: Any = None, passenger: str | None = None) -> MarkerFeed:
    """The opener ``marsupial run`` calls for the feed name ``marker`` (waiting in lockstep);
    ``passenger``: a team passenger's name, whose own camera it reads (``link``, the MAVLink
    link, it does not read)."""
    from mission.time.clock import LockstepClock

    return MarkerFeed(cfg, session, lockstep=isinstance(clock, LockstepClock), passenger=passenger)
