"""Fault injection of the mock vehicle's MAVLink transport.

Each datagram passes a :class:`FaultInjector` on its way in and on its way out. It is dropped
during a blackout window or with probability ``loss_in``/``loss_out``; a surviving datagram is
delayed by ``latency_s`` plus a uniform jitter in ``[0, jitter_s]`` (one-way, applied in each
direction; jitter can reorder datagrams, as UDP may). All times are simulated seconds of the
vehicle's clock, so a fault scenario is the same at any speed factor. Random draws come from a
seeded generator, so a run is reproducible for a given seed and packet sequence.
"""
from __future__ import annotations

import heapq
import itertools
import random
import threading
from dataclasses import dataclass, field
from typing import Any
from mission.core.records import replace


@dataclass(frozen=True)
class FaultOptions:
    """Transport and vehicle faults.

    loss_in, loss_out: probability [0..1] to drop a datagram received / sent.
    latency_s, jitter_s: one-way added delay [s, simulated] and its uniform spread.
    blackouts: windows ``(start_s, duration_s)`` of simulated time since vehicle start during
        which nothing goes in or out.
    refuse_arming_reason: if set, arming is denied with this STATUSTEXT (a failed preflight check).
    refuse_offboard_reason: if set, DO_SET_MODE OFFBOARD is TEMPORARILY_REJECTED with this STATUSTEXT.
    position_lost_at_s: if set, the position estimate is lost at this simulated time since vehicle
        start (as :meth:`sim.vehicle.mock.MockVehicle.lose_position_estimate`), for good.
    seed: seed of the random generator (loss and jitter draws).
    """

    loss_in: float = 0.0
    loss_out: float = 0.0
    latency_s: float = 0.0
    jitter_s: float = 0.0
    blackouts: tuple[tuple[float, float], ...] = field(default_factory=tuple)
    refuse_arming_reason: str | None = None
    seed: int | None = 0
    refuse_offboard_reason: str | None = None
    position_lost_at_s: float | None = None

    def __post_init__(self) -> None:
        for name in ("loss_in", "loss_out"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {value!r}")
        for name in ("latency_s", "jitter_s"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        windows = tuple((float(start), float(duration)) for start, duration in self.blackouts)
        if any(duration < 0 for _, duration in windows):
            raise ValueError(f"blackout durations must be >= 0, got {windows!r}")
        object.__setattr__(self, "blackouts", windows)
        if self.position_lost_at_s is not None and not self.position_lost_at_s >= 0.0:
            raise ValueError(f"position_lost_at_s must be >= 0, got {self.position_lost_at_s!r}")


class FaultInjector:
    """Decides the fate of each datagram and holds the delayed ones until they are due.

    Thread-safe: :meth:`update` may be called from any thread while the vehicle loop runs.
    """

    def __init__(self, options: FaultOptions) -> None:
        self._lock = threading.Lock()
        self.options = options
        self._rng = random.Random(options.seed)
        self._queue: list[tuple[float, int, str, Any]] = []
        self._order = itertools.count()

    def update(self, **changes: Any) -> FaultOptions:
        """Replace some fault options at run time (same names as :class:`FaultOptions`)."""
        with self._lock:
            if "blackouts" in changes:
                changes["blackouts"] = tuple(changes["blackouts"])
            self.options = replace(self.options, **changes)
            if "seed" in changes:
                self._rng = random.Random(changes["seed"])
            return self.options

    def in_blackout(self, t_s: float) -> bool:
        """True if simulated time ``t_s`` falls in a blackout window."""
        return any(start <= t_s < start + duration for start, duration in self.options.blackouts)

    def admit(self, direction: str, t_s: float) -> tuple[str, float]:
        """Fate of a datagram at time ``t_s``: ``("blackout"|"lost"|"now"|"delay", delay_s)``.

        ``direction`` is ``"in"`` or ``"out"``.
        """
        with self._lock:
            opts = self.options
            if self.in_blackout(t_s):
                return "blackout", 0.0
            loss = opts.loss_in if direction == "in" else opts.loss_out
            if loss > 0.0 and self._rng.random() < loss:
                return "lost", 0.0
            delay_s = opts.latency_s + (self._rng.uniform(0.0, opts.jitter_s) if opts.jitter_s > 0 else 0.0)
            return ("delay", delay_s) if delay_s > 0.0 else ("now", 0.0)

    def hold(self, due_s: float, kind: str, item: Any) -> None:
        """Keep ``item`` until simulated time ``due_s``; ``kind`` tells the caller what it is."""
        with self._lock:
            heapq.heappush(self._queue, (due_s, next(self._order), kind, item))

    def due(self, t_s: float) -> list[tuple[str, Any]]:
        """Remove and return the held items due at or before ``t_s``, oldest due first."""
        out: list[tuple[str, Any]] = []
        with self._lock:
            while self._queue and self._queue[0][0] <= t_s + 1e-9:
                _, _, kind, item = heapq.heappop(self._queue)
                out.append((kind, item))
        return out

    def next_due_s(self) -> float | None:
        """Simulated time when the next held item is due, or None."""
        with self._lock:
            return self._queue[0][0] if self._queue else None

    def pending(self) -> int:
        with self._lock:
            return len(self._queue)
