"""What a link's threads share, behind one lock: the identified vehicle, its telemetry, the ACKs,
STATUSTEXTs and parameter values it sent, and the counters. Waits read the injected clock."""
from __future__ import annotations

import collections
import threading
from dataclasses import dataclass, fields
from typing import Callable

from mission.time.clock import Clock
from mission.errors import LinkError, LinkTimeout
from mission.mavlink import telemetry
from mission.mavlink.commands import AckLog
from mission.mavlink.telemetry import VehicleState


@dataclass(frozen=True)
class ParamValue:
    """A parameter as the vehicle last reported it: name, value (decoded), MAV_PARAM_TYPE, and
    the clock time it arrived [s]."""

    name: str
    value: float
    param_type: int
    rx_s: float


@dataclass(frozen=True)
class LinkCounters:
    """Snapshot of the link's packet counters (monotonic since ``open``)."""

    rx_bytes: int = 0
    rx_messages: int = 0
    """Valid packets decoded (any sender, unknown ids included)."""
    rx_bad: int = 0
    """Garbage, CRC, length, signature and parse errors (the receiver survived each)."""
    rx_bad_signature: int = 0
    """Subset of rx_bad: signed packets refused (another key, or a replayed timestamp)."""
    rx_unsigned: int = 0
    """Subset of rx_bad: unsigned packets refused by a signed link (HEARTBEAT included)."""
    rx_unknown: int = 0
    """Valid packets whose message id is not in the dialect (e.g. PX4's 380, 410, 411)."""
    rx_ignored: int = 0
    """Valid packets not applied: before identification, or from another component."""
    rejected_foreign: int = 0
    """Valid packets from a system other than the identified vehicle, and HEARTBEATs of other
    autopilots heard while none was adopted yet."""
    rx_other_link: int = 0
    """Signed packets of the vehicle on another signing link id than the one it was identified
    on (another of its links, forwarded to our port): ignored."""
    rx_other_address: int = 0
    """Unsigned link: packets with the vehicle's ids from another address while its own still
    talks: ignored."""
    peer_moves: int = 0
    """Times the reply address moved after identification (a signed packet of the same link, or
    the old address silent on an unsigned link)."""
    rx_errors: int = 0
    """Socket errors and unexpected handler exceptions in the receiver."""
    tx_messages: int = 0
    tx_heartbeats: int = 0
    tx_setpoints: int = 0
    tx_landing_targets: int = 0
    """LANDING_TARGET packets sent (the deck's landing point for PX4's precision landing)."""
    tx_commands: int = 0
    """COMMAND_LONG and COMMAND_INT packets sent, retries included."""
    tx_errors: int = 0
    command_retries: int = 0
    command_timeouts: int = 0
    command_rejections: int = 0
    log_lines_held: int = 0
    """Per-packet log lines held back by the rate limit (:data:`mission.mavlink.receiver.LIMITER`), in this process."""


class LinkSession:
    """The shared state of one link (``name``: its URL, for messages). Hold :attr:`lock` (or
    :attr:`changed`, the same lock) to read or write the fields; call :meth:`notify_locked`
    after a change so waiters re-check. ``signed``: the link refuses what is not signed with its
    key, so each telemetry sample decides alone (:mod:`mission.mavlink.telemetry`)."""

    def __init__(self, name: str, clock: Clock, position_timeout_s: float, signed: bool = False) -> None:
        self.name, self.clock, self.position_timeout_s = name, clock, position_timeout_s
        self.lock = threading.RLock()  # re-entrant: wait_until predicates may read link.state
        self.changed = threading.Condition(self.lock)
        self.closed = True
        self.vehicle: tuple[int, int] | None = None
        self.telemetry = telemetry.Telemetry(signed=signed)
        self.statustexts: collections.deque[tuple[float, int, str]] = collections.deque(maxlen=500)
        self.position_stamps: collections.deque[float] = collections.deque(maxlen=256)  # LOCAL_POSITION_NED rx [s]
        self.position_stamps_rise = True  # each stamp at or after the one before (a clock never stepped back)
        self.wrong_key: tuple[int, int, int] | None = None  # (sysid, compid, HEARTBEATs) signed with another key
        self.identity_conflict: str | None = None  # a second PX4 autopilot after adoption (target_system unset)
        self.acks = AckLog()
        self.params: dict[str, ParamValue] = {}  # the latest PARAM_VALUE of each name
        self.counts: dict[str, int] = {f.name: 0 for f in fields(LinkCounters)}

    def snapshot_locked(self) -> VehicleState:
        return telemetry.snapshot(self.telemetry, self.clock.now(), self.vehicle, self.position_timeout_s)

    def wait_locked(self, deadline_s: float) -> bool:
        """Wait for a change (lock held) through the clock (which may wake early); False once past
        ``deadline_s`` [s of clock]. Raises :class:`LinkError` if the link is closed."""
        remaining = deadline_s - self.clock.now()
        if remaining <= 0:
            return False
        if self.closed:
            raise LinkError(f"link {self.name!r} is closed")
        self.clock.wait(self.changed, remaining)
        return True

    def wait_until(self, predicate: Callable[[VehicleState], bool], timeout_s: float, what: str) -> VehicleState:
        """Block until ``predicate(snapshot)`` holds; return that snapshot. Raises LinkTimeout
        naming ``what`` after ``timeout_s`` [s of clock]."""
        deadline = self.clock.now() + timeout_s
        with self.changed:
            while True:
                snapshot = self.snapshot_locked()
                if predicate(snapshot):
                    return snapshot
                if not self.wait_locked(deadline):
                    raise LinkTimeout(f"{what} not seen within {timeout_s:g} s on {self.name}")

    def position_rate_hz(self, window_s: float = 1.0) -> float:
        """Rate [Hz of clock] at which LOCAL_POSITION_NED arrived over the last ``window_s`` [s]; 0 when none."""
        now = self.clock.now()
        with self.lock:
            if not self.position_stamps_rise:
                stamps = [t for t in self.position_stamps if now - t <= window_s]
                n, first, last = len(stamps), stamps[0] if stamps else 0.0, stamps[-1] if stamps else 0.0
            else:  # the window's stamps are the newest ones: counted from the end
                n = 0
                for t in reversed(self.position_stamps):
                    if now - t > window_s:
                        break
                    n += 1
                first = self.position_stamps[-n] if n else 0.0
                last = self.position_stamps[-1] if n else 0.0
        return 0.0 if n < 2 else (n - 1) / max(last - first, 1e-9)

    def note_position(self, t_rx: float) -> None:
        """Lock held: a LOCAL_POSITION_NED arrived at ``t_rx`` [s of clock]."""
        if self.position_stamps and t_rx < self.position_stamps[-1]:
            self.position_stamps_rise = False
        self.position_stamps.append(t_rx)

    def signing_problem(self) -> str | None:
        """Why no vehicle was identified on a signed link, if the reason is the key: a PX4
        autopilot was heard, but only with signatures made with another key. None otherwise."""
        with self.lock:
            wrong, vehicle = self.wrong_key, self.vehicle
        if vehicle is not None or wrong is None:
            return None
        return (f"PX4 autopilot sysid {wrong[0]} compid {wrong[1]} signs with another key "
                f"({wrong[2]} HEARTBEATs refused): check mavlink.signing_key_file")

    def identity_problem(self) -> str | None:
        """Why the identified vehicle can no longer be told apart: with ``mavlink.target_system``
        unset, a second PX4 autopilot was heard after one was adopted. None otherwise."""
        with self.lock:
            return self.identity_conflict

    def notify_locked(self) -> None:
        self.clock.notify(self.changed)

    def count(self, *names: str | None, amount: int = 1) -> None:
        with self.lock:
            for name in names:
                if name is not None:
                    self.counts[name] += amount

    def counters(self) -> LinkCounters:
        with self.lock:
            return LinkCounters(**self.counts)
