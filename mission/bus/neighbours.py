"""Receiving the other passengers of a team on the bus: their shared states (thin I/O, no law).

A passenger of a team (``marsupial run --passenger NAME``) hears every teammate's status on its
own key (``marsupial/<pair>/passenger/<name>/state``, :func:`mission.bus.session.keys`), through one
subscriber on :func:`mission.bus.session.team_status_keys`. A callback on Zenoh's thread checks
each sample as the other feeds do: its name must be a teammate's (not this passenger's own, not a
stranger's), else ``unbound``; then size, signature (the pair's key, or with one key per robot the
named teammate's own, :meth:`mission.bus.auth.BusAuth.for_peer`), decode and validation
(:mod:`mission.bus.feeds`, :mod:`mission.bus.wire`); and then:

- each name binds to the first source (the verified signer's stream, else Zenoh's
  ``source_info``) it hears; another source for that name is dropped as ``source`` until the
  bound one has been silent ``max_age_s`` (a restarted passenger is a new source);
- the bound source's statuses must be newer (``stale_seq``, ``stale_stamp``);
- plausible: reported speed at most ``max_speed_m_s`` (``speed``), and no farther from the last
  accepted status than that speed allows over their stamps' difference plus
  :data:`POSITION_SLACK_M` (``jump``; a last status older than ``max_age_s`` allows anything).

A dropped sample is counted per reason, never a crash. :meth:`NeighbourFeed.heard` is the newest
accepted status of each teammate (:class:`Teammate`: position [m], velocity [m/s] local NED, its
receive age [s] on the injected clock, its phase name); the mission's wiring hands them to the
step as :class:`mission.core.safety.Neighbours`. What a stale or silent teammate means is the pure
step's (the barrier leaves out a sample older than ``safety.passenger_separation_max_age_s``).
"""
from __future__ import annotations

import logging
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import zenoh

from mission.bus.auth import BusAuth
from mission.bus.feeds import checked_payload
from mission.bus.session import declare, passenger_of, team_status_keys, undeclare
from mission.bus.wire import PassengerStatus, WireError, decode_passenger_json
from mission.time.clock import Clock

log = logging.getLogger("mission.bus.bridge")  # one logger name for the whole bus

POSITION_SLACK_M = 1.0  # [m] a status may sit this much beyond what its speed allows from the last (estimate noise)


@dataclass
class _Heard:
    source: str
    status: PassengerStatus
    rx_s: float


@dataclass(frozen=True)
class Teammate:
    """A teammate's newest accepted status: its ``name``, position [m] and velocity [m/s] local
    NED (3,), the status's receive age [s] on the feed's clock, and its phase's name; what its
    status shares for the recovery queue (how long its recovery had run [s], its battery [%]; None:
    not shared) and, from the team's file, its MAVLink system id and the target [m] NED (3,) of
    the leg it says it flies (None: not in the roster)."""

    name: str
    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    age_s: float
    phase: str
    recovery_s: float | None = None
    battery_pct: float | None = None
    system_id: int | None = None
    target_ned_m: np.ndarray | None = None


@dataclass(frozen=True)
class Roster:
    """A teammate as the team's file names it: its MAVLink ``system_id`` and the targets [m] NED of
    its legs, in its order (``legs``: a status's ``leg`` indexes them)."""

    system_id: int
    legs: tuple[tuple[float, float, float], ...]

    def target(self, leg: int) -> np.ndarray | None:
        """The target [m] NED (3,) of leg ``leg`` (None: no such leg)."""
        return np.array(self.legs[leg], dtype=float) if 0 <= leg < len(self.legs) else None


class NeighbourFeed:
    """The newest valid status of each of ``team``'s passengers but ``own`` on pair ``pair``
    (see the module docstring); ``auth``: this robot's keys (None: unsigned); ``roster``: each
    teammate's system id and legs from the team's file (:class:`Roster`, by name)."""

    def __init__(self, session: zenoh.Session, pair: str, own: str, team: Sequence[str], clock: Clock, *,
                 max_speed_m_s: float, max_age_s: float = 1.0, auth: BusAuth | None = None,
                 roster: Mapping[str, Roster] | None = None) -> None:
        if not (max_speed_m_s > 0 and max_age_s > 0):
            raise ValueError(f"max_speed_m_s and max_age_s must be > 0, got {max_speed_m_s!r}, {max_age_s!r}")
        self.pair, self.own, self.clock = pair, own, clock
        self.names = tuple(n for n in team if n != own)  # the teammates, in the team's order
        self.roster = dict(roster or {})
        self.max_speed_m_s, self.max_age_s = float(max_speed_m_s), float(max_age_s)
        # each teammate's samples verify with its own key (a team's one key per robot), else the pair's
        self._verifiers = {n: auth.for_peer(n).verifier() for n in self.names} if auth is not None else None
        self._lock = threading.Lock()
        self._heard: dict[str, _Heard] = {}
        self._received = 0
        self._accepted = 0
        self._dropped: dict[str, int] = {}
        self.key = team_status_keys(pair)
        self._sub = declare(f"subscriber on {self.key}", lambda: session.declare_subscriber(self.key, self._on_sample))

    # -- on Zenoh's thread: never block, never call Zenoh
    def _on_sample(self, sample: zenoh.Sample) -> None:
        rx = self.clock.now()
        key = str(sample.key_expr)
        name = passenger_of(key, self.pair)
        if name == self.own:
            return  # our own status, delivered back to our session
        with self._lock:
            self._received += 1
        if name is None or name not in self.names:
            self._drop("unbound", key, "not a teammate's name")
            return
        try:
            raw, source = checked_payload(sample, None if self._verifiers is None else self._verifiers[name])
            status = decode_passenger_json(raw)
        except WireError as exc:
            self._drop(exc.reason, key, str(exc))
            return
        except Exception:  # a bug, not a bad sample: keep Zenoh's thread alive, say it loudly
            log.exception("unexpected error decoding a sample on %s", key)
            self._drop("internal", key, "unexpected error")
            return
        with self._lock:
            reason = self._admit(name, source, status, rx)
            if reason is None:
                self._heard[name] = _Heard(source, status, rx)
                self._accepted += 1
        if reason is not None:
            self._drop(reason, key, f"seq {status.seq} stamp {status.stamp_s} from {source}")

    def _admit(self, name: str, source: str, status: PassengerStatus, rx: float) -> str | None:
        """Lock held: the drop reason of ``status`` of teammate ``name`` from ``source``, or None."""
        if float(np.linalg.norm(status.velocity_ned_m_s)) > self.max_speed_m_s:
            return "speed"
        last = self._heard.get(name)
        if last is None or rx - last.rx_s > self.max_age_s:
            return None  # the first, or after a silence: (re)bound to this source
        if source != last.source:
            return "source"
        if status.seq <= last.status.seq:
            return "stale_seq"
        dt = status.stamp_s - last.status.stamp_s
        if dt < 0:
            return "stale_stamp"
        moved = float(np.linalg.norm(status.position_ned_m - last.status.position_ned_m))
        if moved > self.max_speed_m_s * dt + POSITION_SLACK_M:
            return "jump"
        return None

    def _drop(self, reason: str, key: str, detail: str) -> None:
        with self._lock:
            first = reason not in self._dropped
            self._dropped[reason] = self._dropped.get(reason, 0) + 1
        (log.warning if first else log.debug)("dropped a teammate's status on %s (%s): %s", key, reason, detail)

    # -- caller's thread
    def heard(self) -> list[Teammate]:
        """Every teammate's newest accepted status, aged on the feed's clock [s], in the team's
        order (empty: none heard yet)."""
        now = self.clock.now()
        with self._lock:
            heard = [(n, self._heard[n]) for n in self.names if n in self._heard]
        out = []
        for n, h in heard:
            st, known = h.status, self.roster.get(n)
            out.append(Teammate(n, st.position_ned_m, st.velocity_ned_m_s, max(now - h.rx_s, 0.0), st.phase.value,
                                st.recovery_s, st.battery_pct, None if known is None else known.system_id,
                                None if known is None else known.target(st.leg)))
        return out

    @property
    def counters(self) -> dict[str, Any]:
        """Snapshot: ``{"received", "accepted", "dropped": {reason: n}, "heard": [names], "signed"}``."""
        with self._lock:
            return {"received": self._received, "accepted": self._accepted, "dropped": dict(self._dropped),
                    "heard": sorted(self._heard), "signed": self._verifiers is not None}

    def close(self) -> None:
        """Undeclare the subscriber (idempotent)."""
        sub, self._sub = self._sub, None
        undeclare(sub)
