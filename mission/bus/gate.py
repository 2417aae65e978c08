"""Plausibility gate and source binding of the carrier feed (pure: no Zenoh, no clock).

The carrier feed hands every decoded carrier state to a :class:`FeedGate` with the Zenoh source
it came from and its receive time [s] on the local clock; the gate decides, in O(1) and without
blocking, whether it is accepted.

- Binding: the gate binds to the first source that sends ``bind_samples`` mutually plausible
  states in a row (at most :data:`MAX_CANDIDATES` candidate tracks); until then states drop as
  ``unbound``, afterwards other sources' as ``source`` (counted in :attr:`FeedGate.rejected_sources`).
  :meth:`FeedGate.unbind` starts over. The source is the publisher's Zenoh ``EntityGlobalId`` from
  ``source_info``, or ``"anonymous"``; Zenoh does not authenticate it (mTLS and access control do).
- Plausibility, against the last accepted state of the bound source: ``stale_seq``,
  ``stale_stamp``, ``seq_jump``, ``stamp_jump``, ``speed``, ``jump``, ``gap``, ``velocity``
  (the rules: docs/wire.md). An outlier never becomes the reference; rejected states that form a
  plausible track of ``resync_samples`` replace it (``resyncs``). The separation latch only ever
  sees accepted states.
- Trust (:meth:`FeedGate.distrust`): a new reference (just bound, or a resync whose first state
  does not follow the old reference within the carrier's own limits: a *jump*, counted in
  ``jumps``; a resync after a silence or a burst of late states that does is the same carrier
  moving on) is trusted only once it has stayed within the carrier's own limits (no
  ``speed_margin``; acceleration ``max_accel_m_s2``) for ``settle_s``; a state beyond them starts
  the settle again (``settles``). A bound source whose states drop as stale ``contest_drops`` times within
  ``contest_window_s`` is contested (a second publisher with its source id and a higher
  sequence: an honest ordered stream never does it) until ``settle_s`` after the last one
  (``contests``). The passenger neither rides nor separates on an untrusted state: it holds on the
  dock point it had (docs/security.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MAX_CANDIDATES = 8  # candidate sources tracked while unbound (more are dropped uncounted per source)
MAX_REJECTED_SOURCES = 16  # distinct foreign sources counted by name; the rest under "other"
MAX_SEQ_RATE_HZ = 1000.0  # fastest plausible publishing rate [Hz]
SEQ_SLACK = 100
SPEED_SLACK_M_S = 0.5
VELOCITY_NOISE_M_S = 0.5  # [m/s] velocity change from one state to the next beyond max_accel dt while settling
ANONYMOUS = "anonymous"


@dataclass(frozen=True)
class GateLimits:
    """The carrier's own limits as the gate applies them.

    max_speed_m_s [m/s] the carrier's top speed; speed_margin (>= 1) factor on it;
    position_slack_m [m] localisation noise allowed on top; stamp_slack_s [s] how far the
    sender's stamp may run ahead of the receive-time difference (transport latency variation);
    max_accel_m_s2 [m/s^2] (default: top speed reached in 0.5 s); max_gap_s [s] a silence
    after which a single state is not believed (see ``gap``); bind_samples / resync_samples:
    plausible states in a row needed to bind a source / replace the reference; settle_s [s]
    how long a new reference must stay within the carrier's own limits before it is trusted;
    contest_drops / contest_window_s [s]: stale states of the bound source within that window
    that make it contested (see the module docstring); velocity_noise_m_s [m/s] the velocity
    change from one state to the next allowed beyond the acceleration limit while settling
    (measurement noise: a GNSS velocity's).
    """

    max_speed_m_s: float
    speed_margin: float = 1.5
    position_slack_m: float = 0.5
    stamp_slack_s: float = 2.0
    max_accel_m_s2: float | None = None
    max_gap_s: float = 1.0
    bind_samples: int = 3
    resync_samples: int = 5
    settle_s: float = 2.0
    contest_drops: int = 3
    contest_window_s: float = 1.0
    velocity_noise_m_s: float = VELOCITY_NOISE_M_S

    @property
    def accel_m_s2(self) -> float:
        """The carrier's acceleration limit [m/s^2] (``max_accel_m_s2``, else top speed in 0.5 s)."""
        return self.max_accel_m_s2 if self.max_accel_m_s2 is not None else 2.0 * self.max_speed_m_s

    def __post_init__(self) -> None:
        if not (math.isfinite(self.max_speed_m_s) and self.max_speed_m_s > 0):
            raise ValueError(f"max_speed_m_s must be > 0, got {self.max_speed_m_s!r}")
        if not self.speed_margin >= 1 or not self.position_slack_m >= 0 or not self.stamp_slack_s > 0:
            raise ValueError("speed_margin >= 1, position_slack_m >= 0 and stamp_slack_s > 0 required")
        if self.bind_samples < 1 or self.resync_samples < 2:
            raise ValueError("bind_samples >= 1 and resync_samples >= 2 required")
        if not (self.settle_s >= 0 and self.contest_drops >= 2 and self.contest_window_s > 0):
            raise ValueError("settle_s >= 0, contest_drops >= 2 and contest_window_s > 0 required")


@dataclass(frozen=True)
class Sample:
    """What the gate needs of one state: seq, stamp_s [s] sender clock, position_ned_m [m],
    velocity_ned_m_s [m/s] (local NED, arrays (3,)), rx_s [s] receive time on our clock."""

    seq: int
    stamp_s: float
    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    rx_s: float

    @property
    def lead_s(self) -> float:
        """How far the sender's stamp is ahead of our receive time [s]."""
        return self.stamp_s - self.rx_s


def count_rejected(rejected: dict[str, int], source: str) -> None:
    """Count one sample of a foreign ``source`` in ``rejected`` (at most :data:`MAX_REJECTED_SOURCES`
    names; the rest under ``"other"``)."""
    name = source if source in rejected or len(rejected) < MAX_REJECTED_SOURCES else "other"
    rejected[name] = rejected.get(name, 0) + 1


def implausible(prev: Sample, new: Sample, limits: GateLimits, use_seq: bool, lead_s: float | None = None) -> str | None:
    """The reason ``new`` cannot follow ``prev`` from one carrier (see the module table), or
    None. ``lead_s``: the track's largest ``stamp - rx`` so far (default ``prev.lead_s``)."""
    if use_seq and new.seq <= prev.seq:
        return "stale_seq"
    if new.stamp_s < prev.stamp_s or (not use_seq and new.stamp_s == prev.stamp_s):
        return "stale_stamp"
    dt = new.stamp_s - prev.stamp_s
    drx = max(new.rx_s - prev.rx_s, 0.0)
    if use_seq and new.seq - prev.seq > MAX_SEQ_RATE_HZ * max(dt, drx) + SEQ_SLACK:
        return "seq_jump"
    if new.lead_s > (prev.lead_s if lead_s is None else lead_s) + limits.stamp_slack_s:
        return "stamp_jump"
    v_max = limits.speed_margin * limits.max_speed_m_s
    v = new.velocity_ned_m_s
    if math.sqrt(float(v @ v)) > v_max + SPEED_SLACK_M_S:
        return "speed"
    dp = new.position_ned_m - prev.position_ned_m
    if math.sqrt(float(dp @ dp)) > v_max * dt + limits.position_slack_m:
        return "jump"
    dv = v - prev.velocity_ned_m_s
    a_max = limits.accel_m_s2
    err = dp - 0.5 * (prev.velocity_ned_m_s + v) * dt
    if (math.sqrt(float(dv @ dv)) > a_max * dt + limits.max_speed_m_s
            or math.sqrt(float(err @ err)) > limits.max_speed_m_s * dt + limits.position_slack_m):
        return "velocity"
    return None


def beyond_limits(prev: Sample, new: Sample, limits: GateLimits) -> str | None:
    """Why ``new`` does not follow ``prev`` within the carrier's own limits, strictly (no
    ``speed_margin``; see the module docstring on trust), or None."""
    dt = max(new.stamp_s - prev.stamp_s, 0.0)
    v = new.velocity_ned_m_s
    if math.sqrt(float(v @ v)) > limits.max_speed_m_s + SPEED_SLACK_M_S:
        return "speed"
    dp = new.position_ned_m - prev.position_ned_m
    if math.sqrt(float(dp @ dp)) > limits.max_speed_m_s * dt + limits.position_slack_m:
        return "position"
    dv = v - prev.velocity_ned_m_s
    if math.sqrt(float(dv @ dv)) > limits.accel_m_s2 * dt + limits.velocity_noise_m_s:
        return "acceleration"
    return None


@dataclass
class _Track:
    """A run of mutually plausible samples: the last one, how many, the largest lead [s], when it began."""

    last: Sample
    length: int = 1
    lead_s: float = -math.inf
    first: Sample | None = None  # its first sample (default: ``last``)

    def __post_init__(self) -> None:
        self.lead_s = max(self.lead_s, self.last.lead_s)
        if self.first is None:
            self.first = self.last

    @property
    def first_rx_s(self) -> float:
        """Receive time [s] of its first sample."""
        assert self.first is not None
        return self.first.rx_s

    def fits(self, sample: Sample, limits: GateLimits, use_seq: bool) -> str | None:
        return implausible(self.last, sample, limits, use_seq, self.lead_s)

    def extend(self, sample: Sample) -> None:
        self.last, self.length, self.lead_s = sample, self.length + 1, max(self.lead_s, sample.lead_s)


class FeedGate:
    """Source binding and plausibility for one carrier feed (not thread-safe: the feed locks).

    ``offer(source, sample)`` returns None when the sample is accepted, else the drop reason.
    """

    def __init__(self, limits: GateLimits, use_seq: bool = True) -> None:
        self.limits, self.use_seq = limits, use_seq
        self.bound: str | None = None
        self.resyncs = 0
        self.settles = 0  # new references that had to settle (bind, a jump), and restarts of a settle
        self.jumps = 0  # resyncs onto a track that does not follow the old reference within the carrier's limits
        self.contests = 0  # times the bound source became contested
        self.rejected_sources: dict[str, int] = {}
        self._reference: _Track | None = None
        self._candidates: dict[str, _Track] = {}
        self._resync: _Track | None = None
        self._settle_from: float | None = None  # receive time [s] since which the reference is within limits
        self._why_settling = ""
        self._stale_rx: list[float] = []  # receive times [s] of the bound source's recent stale states
        self._contested_until = -math.inf  # receive time [s]

    def describe_reference(self) -> str:
        """The last accepted sample, for logs."""
        ref = self._reference
        if ref is None:
            return "none"
        last = ref.last
        return (f"seq {last.seq} stamp {last.stamp_s:.3f} rx {last.rx_s:.3f} at "
                f"{np.round(last.position_ned_m, 2).tolist()} m, lead {ref.lead_s:.3f} s")

    def unbind(self) -> None:
        """Forget the bound source and the reference (the carrier went away)."""
        self.bound, self._reference, self._resync = None, None, None
        self._candidates.clear()
        self._stale_rx.clear()
        self._contested_until = -math.inf

    def distrust(self, now_rx_s: float) -> str | None:
        """Why the newest accepted state is not to be trusted at receive time ``now_rx_s`` [s]
        (see the module docstring), or None when it is."""
        ref = self._reference
        if ref is None or self._settle_from is None:
            return "no carrier source bound"
        if now_rx_s < self._contested_until:
            return (f"contested: {len(self._stale_rx)} states of the bound source dropped as stale within "
                    f"{self.limits.contest_window_s:g} s (a second publisher with its source id?)")
        settled = ref.last.rx_s - self._settle_from
        if settled < self.limits.settle_s:
            return f"settling: within the carrier's limits for {settled:.2f} of {self.limits.settle_s:g} s ({self._why_settling})"
        return None

    def _settle(self, rx_s: float, why: str) -> None:
        self._settle_from, self._why_settling = rx_s, why
        self.settles += 1

    def _extended(self, sample: Sample) -> None:
        """The reference was extended by ``sample``: while it settles, check it strictly."""
        assert self._reference is not None and self._settle_from is not None
        prev = self._reference.last
        self._reference.extend(sample)
        if sample.rx_s - self._settle_from < self.limits.settle_s:
            beyond = beyond_limits(prev, sample, self.limits)
            if beyond is not None:
                self._settle(sample.rx_s, f"{beyond} beyond the carrier's limits")

    def _stale(self, rx_s: float) -> None:
        """A state of the bound source dropped as stale: contested after contest_drops in the window."""
        window = self.limits.contest_window_s
        self._stale_rx = [t for t in self._stale_rx if rx_s - t <= window][-(self.limits.contest_drops - 1):] + [rx_s]
        if len(self._stale_rx) >= self.limits.contest_drops:
            if rx_s >= self._contested_until:
                self.contests += 1
            self._contested_until = rx_s + self.limits.settle_s

    def offer(self, source: str, sample: Sample) -> str | None:
        if self.bound is None:
            return self._offer_unbound(source, sample)
        if source != self.bound:
            count_rejected(self.rejected_sources, source)
            return "source"
        assert self._reference is not None
        if sample.rx_s - self._reference.last.rx_s > self.limits.max_gap_s:
            reason: str | None = "gap"
        else:
            reason = self._reference.fits(sample, self.limits, self.use_seq)
        if reason is None:
            self._extended(sample)
            self._resync = None
            return None
        if reason in ("stale_seq", "stale_stamp"):
            self._stale(sample.rx_s)
        track = self._resync
        if track is not None and track.fits(sample, self.limits, self.use_seq) is None:
            track.extend(sample)
        else:
            self._resync = track = _Track(sample)
        if track.length >= self.limits.resync_samples:
            old, self._reference, self._resync = self._reference.last, track, None
            self.resyncs += 1
            assert track.first is not None
            jumped = beyond_limits(old, track.first, self.limits)
            if jumped is not None:  # not the same carrier moving on (a silence, a burst of late states): a jump
                self.jumps += 1
                self._settle(track.first_rx_s, f"after a resync: {jumped} beyond the carrier's limits")
            return None
        return reason

    def _offer_unbound(self, source: str, sample: Sample) -> str | None:
        track = self._candidates.get(source)
        if track is not None and track.fits(sample, self.limits, self.use_seq) is None:
            track.extend(sample)
        elif track is not None or len(self._candidates) < MAX_CANDIDATES:
            self._candidates[source] = track = _Track(sample)
        else:
            return "unbound"
        if track.length < self.limits.bind_samples:
            return "unbound"
        self.bound, self._reference = source, track
        self._candidates.clear()
        self._settle(track.first_rx_s, "just bound")
        return None
