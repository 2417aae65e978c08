"""The carrier's clock against ours, from signed round trips, and a sample's age (pure: no
sockets, no clock of its own).

A round trip: we send a ping at ``sent_s`` (our clock), the carrier answers with its own clock
``remote_s``, the answer arrives at ``received_s``. Whatever the path's delays, the carrier read
its clock between our two instants, so its offset (carrier clock minus ours) lies in
``[remote_s - received_s, remote_s - sent_s]``: the midpoint, with half the round trip as the
bound of its error. :class:`OffsetEstimator` keeps the round trips of the last ``window_s`` and
answers with the tightest (the smallest round trip), its bound widened by the clocks' drift since
it was measured. A relay that delays the pings as well as the states widens the bound by the
delay: it can hide nothing, only make the age unknown.

A sample's age is then ``now - (stamp - offset)`` [s]: the time since the carrier *measured*
it, not since it arrived (:func:`sample_age`), good to ``bound_s``. In lockstep the carrier steps
on our simulated clock: the offset is 0 exactly (:data:`SHARED_CLOCK`).

Faults (:meth:`OffsetEstimator.add` returns the reason, the round trip is not used): a round trip
longer than ``max_round_trip_s`` (``rtt``), one that does not fit the round trips before it
(``inconsistent``: the carrier's clock jumped, or an answer was forged or replayed; after
``restart_after`` of them in a row the estimator starts over from the new ones: a restarted
carrier's clock, counted as ``restarted``), one that answers no ping of ours (``unknown``, counted
by the I/O side). Times in [s].
"""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class OffsetEstimate:
    """The carrier's clock minus ours, ``offset_s`` [s], with ``|error| <= bound_s`` [s]."""

    offset_s: float
    bound_s: float


#: The carrier and we step on one clock (lockstep simulation): no offset, no error.
SHARED_CLOCK = OffsetEstimate(0.0, 0.0)


class SharedClock:
    """The offset source of a lockstep run: the carrier steps on our clock (:data:`SHARED_CLOCK`).
    The same interface as :class:`mission.bus.timesync.ClockPing`: ``estimate()``, ``snapshot()``."""

    def estimate(self) -> OffsetEstimate:
        return SHARED_CLOCK

    def snapshot(self) -> dict[str, object]:
        return {"shared": True, "offset_s": 0.0, "bound_s": 0.0}


@dataclass(frozen=True)
class RoundTrip:
    """One ping and its answer: sent and received on our clock, ``remote_s`` on the carrier's [s]."""

    sent_s: float
    remote_s: float
    received_s: float

    @property
    def rtt_s(self) -> float:
        return self.received_s - self.sent_s

    @property
    def estimate(self) -> OffsetEstimate:
        """Its offset interval as midpoint and half-width."""
        return OffsetEstimate(self.remote_s - 0.5 * (self.sent_s + self.received_s), 0.5 * self.rtt_s)


@dataclass
class OffsetEstimator:
    """The tightest recent round trip (see the module docstring).

    window_s [s]: how long a round trip is used; max_round_trip_s [s]: longer ones are refused;
    drift: how fast the two clocks may part [s/s] (crystal clocks: 1e-4 is generous);
    slack_s [s]: how far a new round trip may lie outside the current interval before it is
    ``inconsistent``.
    """

    window_s: float = 30.0
    max_round_trip_s: float = 1.0
    drift: float = 1e-4
    slack_s: float = 0.002
    restart_after: int = 4
    trips: list[RoundTrip] = field(default_factory=list)
    refused: dict[str, int] = field(default_factory=dict)
    _inconsistent_run: int = 0

    def add(self, trip: RoundTrip) -> str | None:
        """Take ``trip``; the reason it was refused (``rtt``, ``inconsistent``), or None."""
        why = None
        if not (math.isfinite(trip.sent_s) and math.isfinite(trip.remote_s) and math.isfinite(trip.received_s)) \
                or not 0.0 <= trip.rtt_s <= self.max_round_trip_s:
            why = "rtt"
        else:
            current = self.estimate(trip.received_s)
            new = trip.estimate
            if current is not None and abs(new.offset_s - current.offset_s) > current.bound_s + new.bound_s + self.slack_s:
                self._inconsistent_run += 1
                if self._inconsistent_run < self.restart_after:
                    why = "inconsistent"
                else:  # the carrier's clock has moved for good (a restarted carrier): start over
                    self.refused["restarted"] = self.refused.get("restarted", 0) + 1
                    self.trips, self._inconsistent_run = [], 0
            else:
                self._inconsistent_run = 0
        if why is not None:
            self.refused[why] = self.refused.get(why, 0) + 1
            return why
        self.trips = [t for t in self.trips if trip.received_s - t.received_s <= self.window_s] + [trip]
        return None

    def estimate(self, now_s: float) -> OffsetEstimate | None:
        """The offset at ``now_s`` [s] (our clock) from the tightest round trip of the window,
        its bound grown by the drift since; None without one."""
        best: OffsetEstimate | None = None
        for t in self.trips:
            age = now_s - t.received_s
            if age > self.window_s:
                continue
            e = t.estimate
            bound = e.bound_s + self.drift * max(age, 0.0)
            if best is None or bound < best.bound_s:
                best = OffsetEstimate(e.offset_s, bound)
        return best


def sample_age(now_s: float, stamp_s: float, offset: OffsetEstimate) -> float:
    """Age [s] at ``now_s`` (our clock) of a sample the carrier stamped ``stamp_s`` (its clock):
    the time since it measured it, good to ``offset.bound_s``."""
    return now_s - (stamp_s - offset.offset_s)


@dataclass
class DelayWatch:
    """Whether the carrier's states arrive later than they did: each accepted state's transit
    ``rx - (stamp - offset)`` [s] against the least of the last ``window_s`` [s]. A transit more
    than ``growth_s`` [s] above that least is a growing delay (a relay holding the states, a
    congested link): :meth:`add` returns its reason once per episode (it ends when the transit
    falls back within ``growth_s / 2``), and counts it in :attr:`growths`."""

    window_s: float = 10.0
    growth_s: float = 0.1
    growths: int = 0
    last: str = ""
    _recent: collections.deque[tuple[float, float]] = field(default_factory=collections.deque)  # (rx [s], transit [s])
    # those of them that no later one undercuts, oldest first: the first is the window's least
    # (a sliding-window minimum: O(1) a state while the states arrive in order)
    _least: collections.deque[tuple[float, float]] = field(default_factory=collections.deque)
    _in_order: bool = True  # every state received at or after the one before
    _growing: bool = False

    def add(self, rx_s: float, transit_s: float) -> str | None:
        recent, window = self._recent, self.window_s
        if (recent and rx_s < recent[-1][0]) or math.isnan(rx_s) or math.isnan(transit_s):
            self._in_order = False  # a clock stepped back (or a NaN): from now on the whole window is searched
        if self._in_order:
            least_of = self._least
            while recent and rx_s - recent[0][0] > window:
                recent.popleft()
            while least_of and rx_s - least_of[0][0] > window:
                least_of.popleft()
            while least_of and least_of[-1][1] >= transit_s:
                least_of.pop()
            least_of.append((rx_s, transit_s))
            recent.append((rx_s, transit_s))
            least = least_of[0][1]
        else:
            self._recent = collections.deque([(t, d) for t, d in recent if rx_s - t <= window] + [(rx_s, transit_s)])
            least = min(d for _, d in self._recent)
        if transit_s - least > self.growth_s:
            if self._growing:
                return None
            self._growing = True
            self.growths += 1
            self.last = (f"carrier states arrive {transit_s:.2f} s after the carrier measured them, "
                         f"{transit_s - least:.2f} s later than within the last {self.window_s:g} s")
            return self.last
        if transit_s - least <= self.growth_s / 2:
            self._growing = False
        return None

