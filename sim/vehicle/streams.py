"""When the mock vehicle sends each telemetry stream, per link (PX4 keeps a stream table per
MAVLink instance: SET_MESSAGE_INTERVAL changes only the link it arrived on).

Times are simulated seconds [s]. What the messages contain is :mod:`sim.vehicle.telemetry`'s.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from typing import Protocol

from sim.vehicle import telemetry as tel
DUE_EPSILON = 1e-9  # [s] tolerance when comparing due times with the step grid


class Named(Protocol):
    name: str


class StreamSchedule:
    """The streams of every link, at PX4's onboard-profile rates until someone asks otherwise.
    ``speed``: the clock's speed factor (the wall-clock caps of :mod:`sim.vehicle.telemetry`)."""

    def __init__(self, link_names: Iterable[str], speed: float) -> None:
        self.speed = speed
        self._streams = {name: tel.make_streams(speed) for name in link_names}

    def of(self, link_name: str, msg_id: int) -> tel.Stream | None:
        """The stream of message ``msg_id`` on link ``link_name`` (None: not a stream of PX4's)."""
        return next((s for s in self._streams[link_name].values() if s.msg_id == msg_id), None)

    def set_interval(self, stream: tel.Stream, interval_us: float, t_s: float) -> None:
        """PX4's reading of SET_MESSAGE_INTERVAL's interval [us]: < 0 stops the stream, 0 (or NaN)
        restores its default rate, > 0 sets it (delivered up to the stream's source rate); the
        next message is due at ``t_s``."""
        if interval_us < -1e-5:
            rate_hz = 0.0
        elif interval_us > 1e-5:
            rate_hz = 1e6 / interval_us
        else:
            rate_hz = stream.default_rate_hz
        stream.set_rate(rate_hz, self.speed)
        stream.next_due_s = t_s

    def due(self, links: Iterable[Named], t_s: float) -> Iterator[tuple[Named, tel.Stream]]:
        """The (link, stream) pairs due at ``t_s``, each moved on to its next due time."""
        for link in links:
            for stream in self._streams[link.name].values():
                if stream.period_s <= 0 or stream.next_due_s > t_s + DUE_EPSILON:
                    continue
                yield link, stream
                stream.next_due_s += stream.period_s
                if stream.next_due_s <= t_s:
                    stream.next_due_s = t_s + stream.period_s

    def skip(self, links: Iterable[Named], t_s: float) -> None:
        """Move the streams due at ``t_s`` on to their next due time, sending nothing."""
        for _ in self.due(links, t_s):
            pass

    def next_due_s(self, links: Iterable[Named]) -> float:
        """Earliest due time [s] of any running stream of ``links`` (inf: none runs)."""
        return min((s.next_due_s for link in links for s in self._streams[link.name].values() if s.period_s > 0),
                   default=math.inf)
