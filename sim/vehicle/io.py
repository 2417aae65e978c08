"""The mock vehicle's links as its fault injection lets them be.

Inbound: poll the sockets, pass each datagram through the link faults (lost, delayed, blacked
out; lockstep clock messages bypass them) to :class:`sim.vehicle.handlers.MessageHandlers`.
Outbound: encode, count, pass through the faults, then send one message per datagram as PX4
does, or, in lockstep, queue the step's packets behind its SYSTEM_TIME for one datagram per link;
the commander's STATUSTEXTs go to the links whose peer is alive.
All fault times are simulated seconds at the vehicle's current step.
"""
from __future__ import annotations

import logging
import select
from typing import TYPE_CHECKING, Any

from sim.vehicle import telemetry as tel
from sim.vehicle.endpoints import VehicleLink
from sim.vehicle.lockstep import is_timesync

if TYPE_CHECKING:
    from sim.vehicle.mock import MockVehicle

RX_BATCH = 256  # datagrams read per socket per pass
STATUSTEXT_PEER_TIMEOUT_S = 2.5  # PX4 treats a peer without HEARTBEAT for this long as gone

log = logging.getLogger("sim.vehicle.mock")


class LinkIO:
    """Receiving and sending for :class:`~sim.vehicle.mock.MockVehicle` ``v`` (its links, faults and
    counters; every method but :meth:`poll` runs with the vehicle's lock held)."""

    def __init__(self, vehicle: MockVehicle) -> None:
        self.v = vehicle
        self._chunk_id = 0  # the last STATUSTEXT chunk id

    def poll(self, wait_s: float) -> None:
        links = list(self.v._links)
        try:
            ready, _, _ = select.select([link.sock for link in links], [], [], wait_s)
        except (OSError, ValueError):  # closed by stop()
            return
        for link in links:
            if link.sock in ready:
                self._drain(link)

    def _drain(self, link: VehicleLink) -> None:
        for _ in range(RX_BATCH):
            try:
                data, address = link.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return
            with self.v._lock:
                self.v._advance_to(self.v.clock.now())
                if self.v._lockstep is not None and is_timesync(data):
                    self.v._lockstep.clock_message(link, data, address)
                else:
                    self._admit_in(link, data, address)
                self.flush()

    def _admit_in(self, link: VehicleLink, data: bytes, address: tuple[str, int]) -> None:
        if self._passes("in", (link, data, address)):
            self.v._handlers.process(link, data, address)

    def _passes(self, direction: str, item: tuple) -> bool:
        """Through the faults of ``direction`` ("in" or "out"): True to deliver ``item`` now;
        otherwise it was lost, blacked out or held back for later (:meth:`release`), and counted."""
        fate, delay_s = self.v._faults.admit(direction, self.v._t_s)
        if fate == "blackout":
            self.v._counters[f"blackout_{direction}"] += 1
        elif fate == "lost":
            self.v._counters[f"dropped_{direction}"] += 1
        elif fate == "delay":
            self.v._counters[f"delayed_{direction}"] += 1
            self.v._faults.hold(self.v._t_s + delay_s, direction, item)
        else:
            return True
        return False

    def release(self, kind: str, item: Any) -> None:
        if kind == "in":
            self.v._handlers.process(*item)
        else:
            link, data = item
            if link.target is not None and link in self.v._links:
                self._emit(link, data)

    def send(self, link: VehicleLink, msg: Any) -> None:
        """Encode ``msg`` on ``link`` and send it through the outbound faults."""
        if self.v._lockstep is not None:  # the step's SYSTEM_TIME goes first: encode (and sign) it first, or
            self.v._lockstep.mark_time(link)  # a signing peer takes this packet's older timestamp for a replay
        data = link.pack(msg)
        self.v._counters["tx_messages"] += 1
        if self._passes("out", (link, data)) and link.target is not None:
            self._emit(link, data)

    def _emit(self, link: VehicleLink, data: bytes) -> None:
        """Send a packet that passed the faults: now (one per datagram, as PX4), or in lockstep
        with the rest of its step (:meth:`flush`), behind the step's SYSTEM_TIME."""
        stepper = self.v._lockstep
        if stepper is not None:
            stepper.mark_time(link)
        if stepper is not None and stepper.batching:
            link.queue(data)
        elif not link.sendto(data, link.target):  # type: ignore[arg-type]  (the caller checked)
            self.v._counters["tx_errors"] += 1

    def send_statustexts(self) -> None:
        """Send the commander's STATUSTEXTs to the links whose peer is alive (PX4 rule)."""
        v = self.v
        v._collect_events()
        unsent, v._unsent = v._unsent, []
        for _, severity, text in unsent:
            log.info("STATUSTEXT %s", text)
            self._chunk_id = self._chunk_id % 65535 + 1
            for link in v._links:
                peer_alive = v._t_s - link.last_peer_heartbeat_s <= STATUSTEXT_PEER_TIMEOUT_S
                if peer_alive or not v.options.statustext_needs_heartbeat:
                    for chunk in tel.statustext_chunks(severity, text, self._chunk_id):
                        self.send(link, chunk)

    def flush(self) -> None:
        """Send each link's batch of this step as one datagram (lockstep)."""
        for link in self.v._links:
            self.v._counters["tx_errors"] += link.flush()
