"""Lockstep simulated time over MAVLink (the protocol: :mod:`mission.bus.lockstep`).

:class:`MavlinkUpstream` is the controller's side of the mock vehicle's clock (SYSTEM_TIME, the
TIMESYNC barriers and their answers); :class:`MavlinkRelay` brings a carrier's own lockstep
vehicle (the mock rover) along the same way.
"""
from __future__ import annotations

import logging
import threading
import time
from typing import Any

from mission.mavlink.env import mavlink
from mission.time.clock import CARRIER_WATCHDOG_WALL_S, HELLO_WALL_S, LockstepClock

log = logging.getLogger(__name__)


class MavlinkUpstream:
    """The controller's side of the vehicle's clock: reads SYSTEM_TIME / TIMESYNC from ``link``
    and answers the barriers. ``link`` is a :class:`mission.mavlink.link.VehicleLink`."""

    def __init__(self, clock: LockstepClock, link: Any) -> None:
        self.clock, self.link = clock, link
        link.add_listener(self._on_message)
        clock.upstream = self

    def _on_message(self, msg: Any) -> None:
        kind = msg.get_type()
        if kind == "SYSTEM_TIME":
            self.clock.advance(int(msg.time_boot_ms) * 1_000_000)
        elif kind == "TIMESYNC" and msg.tc1 == 0:
            self.clock.barrier(int(msg.ts1))

    def report(self, t_ns: int, wake_ns: int) -> None:
        self.link.send_message(mavlink.MAVLink_timesync_message(wake_ns, t_ns))

    def working(self, t_ns: int) -> None:
        """Still working on step ``t_ns`` (``TIMESYNC(tc1 t, ts1 t)``: a wake that is not after
        ``t`` answers nothing): the vehicle keeps waiting rather than taking us for gone."""
        if t_ns > 0:  # tc1 0 is a TIMESYNC request
            self.link.send_message(mavlink.MAVLink_timesync_message(t_ns, t_ns))


class MavlinkRelay:
    """A process brings its own lockstep vehicle on ``link`` along (a :class:`~mission.time.clock.Downstream`):
    at each step ``t`` it answers the vehicle's barrier with wake ``t`` and waits until the
    vehicle stopped at its next barrier (at or after ``t``: it integrates whole physics steps),
    its telemetry up to then received ahead of that barrier on the same socket.

    The vehicle is dropped after ``watchdog_wall_s`` without progress (``join_wall_s`` before it
    first answered); it then goes on in real time after its own watchdog, and the state it
    stops sending is what the carrier's own-state watchdog is for. ``link`` is a
    :class:`mission.mavlink.link.VehicleLink`."""

    def __init__(self, link: Any, *, watchdog_wall_s: float = CARRIER_WATCHDOG_WALL_S, join_wall_s: float = 30.0) -> None:
        self.link, self.watchdog_wall_s, self.join_wall_s = link, watchdog_wall_s, join_wall_s
        self._cv = threading.Condition()
        self._at_ns: int | None = None  # the barrier the vehicle waits at
        self._heard = 0  # barrier messages received (the vehicle sends one again when unanswered)
        self._joined = False
        self.dropped = False  # it fell silent
        self.left = False  # we left the lockstep
        link.add_listener(self._on_message)

    def _on_message(self, msg: Any) -> None:
        if msg.get_type() == "TIMESYNC" and msg.tc1 == 0:
            with self._cv:
                self._at_ns = max(self._at_ns if self._at_ns is not None else -1, int(msg.ts1))
                self._heard += 1
                self._cv.notify_all()

    def wake_ns(self) -> int | None:
        return None  # the vehicle needs no step of its own: it is brought to each of ours

    def run(self, t_ns: int) -> None:
        if self.dropped or self.left:
            return
        limit = self.watchdog_wall_s if self._joined else self.join_wall_s
        start, answered = time.monotonic(), -1
        with self._cv:
            while self._at_ns is None or self._at_ns < t_ns:
                if self._at_ns is not None and self._heard != answered:  # a barrier, new or sent again
                    answered, at = self._heard, self._at_ns
                    self._cv.release()
                    try:
                        self.link.send_message(mavlink.MAVLink_timesync_message(t_ns, at))
                    finally:
                        self._cv.acquire()
                if time.monotonic() - start > limit:
                    self.dropped = True
                    log.warning("lockstep: the vehicle did not reach t = %.3f s within %.1f s (wall); going on "
                                "without it", t_ns / 1e9, limit)
                    return
                self._cv.wait(HELLO_WALL_S)
            self._joined = True

    def leave(self) -> None:
        """Let the vehicle go on in real time now (this process left the lockstep)."""
        with self._cv:
            at = self._at_ns
        if at is not None and not (self.dropped or self.left):
            self.left = True
            try:
                self.link.send_message(mavlink.MAVLink_timesync_message(-1, at))
            except Exception as exc:  # noqa: BLE001 - leaving must not fail
                log.debug("lockstep leave to the vehicle not sent: %s", exc)
