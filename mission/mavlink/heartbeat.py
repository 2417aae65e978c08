"""Our own HEARTBEAT, as a companion computer sends it: an onboard controller (type 18), no
autopilot (8), active, every ``period_s`` of the injected clock, and once at once when the vehicle
is found (PX4 sends STATUSTEXT reasons only to peers that sent a HEARTBEAT; it drops a peer 2.5 s
after its last one)."""
from __future__ import annotations

import logging
import threading
from typing import Any, Callable

from mission.time.clock import Clock
from mission.errors import LinkError
from mission.mavlink.env import mavlink

log = logging.getLogger("mission.mavlink.link")


def our_heartbeat() -> Any:
    """Our HEARTBEAT: an onboard controller (18), no autopilot (8), active."""
    return mavlink.MAVLink_heartbeat_message(
        mavlink.MAV_TYPE_ONBOARD_CONTROLLER, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE, 3
    )


class HeartbeatSender:
    """Sends :func:`our_heartbeat` through ``send(msg, counter)``; ``after_send()`` runs after each
    periodic one (the link flushes its tlog). :meth:`run` is the thread; :meth:`stop` ends it."""

    def __init__(self, send: Callable[[Any, str], bool], clock: Clock, period_s: float,
                 after_send: Callable[[], None]) -> None:
        self.send, self.clock, self.period_s, self.after_send = send, clock, period_s, after_send
        self._cond = threading.Condition()
        self._stop = threading.Event()

    def run(self) -> None:
        """Until :meth:`stop`: send, then wait ``period_s`` on the clock (a lockstep participant)."""
        while not self._stop.is_set():
            try:
                self.send(our_heartbeat(), "tx_heartbeats")
                self.after_send()
            except LinkError as exc:
                if not self._stop.is_set():
                    log.warning("heartbeat not sent: %s", exc)
            except Exception:  # pragma: no cover - the heartbeat must keep beating
                log.exception("heartbeat thread error")
            deadline = self.clock.now() + self.period_s
            with self._cond:
                while not self._stop.is_set() and (remaining := deadline - self.clock.now()) > 0:
                    self.clock.wait(self._cond, remaining)

    def announce(self, source: tuple[int, int]) -> None:
        """The vehicle ``source`` was just identified: one HEARTBEAT now, before any command."""
        try:
            self.send(our_heartbeat(), "tx_heartbeats")
        except LinkError as exc:
            log.warning("heartbeat not sent: %s", exc)

    def stop(self) -> None:
        self._stop.set()
        with self._cond:
            self.clock.notify(self._cond)
