"""The relative estimator: where the deck is from the passenger, with no shared frame.

:class:`RelativeEstimator` fuses, into the state of :mod:`mission.relnav.kalman` (the carrier's
reference point and velocity in the passenger's GNSS frame, the bias between the carrier's
and the passenger's GNSS frames, and the drift rate of the passenger's own estimate):

- the passenger's own estimate, every tick (:meth:`RelativeEstimator.tick`): it sets the time,
  and the relative position is the carrier's less it (the vehicle's own manoeuvres are an input,
  never a disturbance the model must absorb);
- the carrier's reported GNSS state (:meth:`RelativeEstimator.carrier`), stamped with its
  measurement time: its position sees ``c + b``, its velocity ``w``; the acceleration the carrier
  measured and sent beside it is the model's known input from that time until the next fix (it
  was measured when the fix was published, up to the fix's latency later: so the velocity moves
  on through that latency as the carrier's does, where a constant-velocity prediction lags a
  carrier pulling away by its acceleration times the latency and more);
- the marker (:meth:`RelativeEstimator.marker`), stamped with its capture time: the deck from the
  vehicle plus the vehicle's own position then sees ``c``, with the detector's covariance plus
  ``marker_model_sigma_m`` squared per axis (what the detector cannot know of);
- with ``own_drift_sigma_m_s`` > 0, the passenger's own position estimate drifts at a rate ``d``,
  a state: the deck moves in the passenger's frame at ``w + d`` (the marker shows it, the GNSS
  velocity does not), which it keeps through a marker loss;
- a downward range (:meth:`RelativeEstimator.range`), stamped with its capture time: over the
  deck the deck's top is the vehicle's own position then plus the range straight down, so it sees
  ``c``'s height (the deck's top less its offset from the reference point), which the vehicle's
  own height estimate does not carry; fused only while the estimate has the vehicle over the deck
  (within its radius less ``range_deck_margin_m``; else it measured the ground: counted ``off_deck``),
  through its own one-degree gate ``range_gate_nis``;
- standing on the deck (:meth:`RelativeEstimator.seated`): the carrier where the vehicle stands,
  its height included, an error that stays the same for as long as it stands, so fused only up
  to its own standard deviation.

Measurements arrive late and out of order. Each is fused at its own time: the estimator keeps
the last ``history_s`` of ticks and measurements with the state after each tick, and a late one
restarts the filter from the newest state before it and replays everything after it in time
order. So the result depends on what was measured, not on the order it arrived in; a
measurement stamped after the newest tick waits for a tick to pass it, one older than the
history is dropped (counted ``too_old``), and so is one stamped more than ``history_s`` after
the newest tick (``too_new``: its clock disagrees). Each measurement passes a chi-square gate on its
normalised innovation squared (a flipped pose, another tag's detection), and the rejections are
counted. Deterministic, no I/O, no clock: time is what the inputs say [s].
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np

from mission.relnav import kalman
from mission.relnav.inputs import CarrierFix, Counts, MarkerFix, MarkerObservation, OwnSample, RangeFix, RelativeEstimate

UNKNOWN_M = 1e3  # [m] the standard deviation of what a measurement does not measure (a seated axis known already)
KINDS = ("marker", "gnss_position", "gnss_velocity", "seated", "range")
_RESET = "reset"  # an event's outcome: it re-initialised the uncertainty (counted as fused, reported as Counts.resets)
_OFF_DECK = "off_deck"  # a range's outcome: the estimate had the vehicle off the deck (counted as fused, reported as Counts.off_deck)
H_HEIGHT = kalman.H_MARKER[2:3]  # a range sees the carrier's reference point's height
# at one time: the GNSS state, then the marker (and the range), then the tick's snapshot (a fixed order, so that the
# result does not depend on the order of arrival)
_GNSS, _MARKER, _TICK = 0, 1, 2


@dataclass(frozen=True)
class RelnavParams:
    """The estimator's tuning, from ``[relnav]`` (:meth:`mission.config.relnav.RelnavSection.params`, where the
    meanings, units and defaults are)."""

    accel_noise_m_s2: float
    bias_sigma_m: float
    vertical_factor: float
    bias_tau_s: float
    gnss_position_sigma_m: float
    gnss_velocity_sigma_m_s: float
    initial_sigma_m: float
    initial_velocity_sigma_m_s: float
    gate_nis: float
    marker_reset_s: float
    history_s: float
    converged_sigma_m: float
    own_drift_sigma_m_s: float
    own_drift_tau_s: float
    accel_vertical_factor: float
    range_gate_nis: float
    range_deck_margin_m: float
    marker_model_sigma_m: float


@dataclass
class _Event:
    """A tick or a measurement in the history, in time order by ``key``; ``outcome`` per kind
    (fused or not) from its last fusion."""

    key: tuple[float, int, int]
    tick: OwnSample | None = None
    fix: CarrierFix | None = None
    marker: MarkerObservation | None = None
    seated: bool = False  # ``marker`` is the seated pseudo-measurement (fused up to its own sigma)
    range: RangeFix | None = None
    outcome: dict[str, bool] = field(default_factory=dict)

    @property
    def t_s(self) -> float:
        return self.key[0]


@dataclass(frozen=True)
class _Snapshot:
    """The filter right after the tick of ``key``."""

    key: tuple[float, int, int]
    x: np.ndarray
    p: np.ndarray
    marker_t_s: float
    rejected_since_s: float
    accel: np.ndarray


class RelativeEstimator:
    """The relative position, velocity and GNSS-frame bias from GNSS and the marker (module docstring)."""

    def __init__(self, params: RelnavParams) -> None:
        self.params = params
        self._events: list[_Event] = []  # the history, sorted by key
        self._snapshots: list[_Snapshot] = []  # after each tick in the history, sorted by key
        self._own: list[OwnSample] = []  # the passenger's samples in the history, by time
        self._seq = 0
        self._x = np.zeros(kalman.N)
        self._p = self._prior()
        self._accel = np.zeros(3)  # [m/s^2] NED the carrier's acceleration it sent with its newest fix fused (the input)
        self._t_s = -math.inf  # the time of the filter's state
        self._marker_t_s = -math.inf  # capture time of the newest marker fused
        self._rejected_since_s = math.inf  # capture time of the first marker rejected since the last one fused
        self._done: tuple[float, int, int] | None = None  # the last event the state includes
        self._replay_from: tuple[float, int, int] | None = None  # the earliest event fused out of order
        self._fused = dict.fromkeys((*KINDS, _RESET, _OFF_DECK), 0)  # by each measurement's latest fusion
        self._rejected = dict.fromkeys(KINDS, 0)
        self._too_old = 0
        self._too_new = 0
        self._models: dict[float, tuple[np.ndarray, np.ndarray]] = {}  # (transition, process noise) by step [s]

    def _prior(self) -> np.ndarray:
        p = self.params
        return np.diag([p.initial_sigma_m ** 2] * 3 + [p.initial_velocity_sigma_m_s ** 2] * 3
                       + list(self._per_axis(p.bias_sigma_m) ** 2) + list(self._per_axis(p.own_drift_sigma_m_s) ** 2))

    def _per_axis(self, horizontal: float) -> np.ndarray:
        """A horizontal standard deviation per NED axis (the vertical one times ``vertical_factor``)."""
        return np.array([horizontal, horizontal, horizontal * self.params.vertical_factor])

    # --- inputs -----------------------------------------------------------------------------

    def tick(self, own: OwnSample) -> RelativeEstimate:
        """The passenger's own estimate at ``own.t_s`` [s] (later than the last tick's, finite; else
        ValueError): the filter moves on to that time, fusing what has arrived; returns the
        estimate then."""
        if self._own and not own.t_s > self._own[-1].t_s:
            raise ValueError(f"tick at {own.t_s!r} s is not after the last one at {self._own[-1].t_s!r} s")
        if not (np.all(np.isfinite(own.position_ned_m)) and np.all(np.isfinite(own.velocity_ned_m_s))):
            raise ValueError(f"the passenger's own estimate at {own.t_s!r} s is not finite")
        event = _Event(self._key(own.t_s, _TICK), tick=own)
        self._own.append(own)
        self._insert(event)
        self._catch_up()
        self._prune()
        return self.estimate()

    def carrier(self, fix: CarrierFix) -> None:
        """The carrier's reported GNSS state, measured at ``fix.t_s`` [s]; fused at the next
        :meth:`tick` or :meth:`estimate`."""
        self._add(_Event(self._key(fix.t_s, _GNSS), fix=fix))

    def marker(self, observation: MarkerObservation) -> None:
        """A marker's measurement captured at ``observation.capture_t_s`` [s] (the carrier's
        reference point less the vehicle's, NED [m]); fused at the next :meth:`tick` or
        :meth:`estimate`."""
        self._add(_Event(self._key(observation.capture_t_s, _MARKER), marker=observation))

    def range(self, fix: RangeFix) -> None:
        """A downward range captured at ``fix.t_s`` [s]; fused at the next :meth:`tick` or
        :meth:`estimate`, if the estimate then has the vehicle over the deck (module docstring)."""
        self._add(_Event(self._key(fix.t_s, _MARKER), range=fix))

    def seated(self, t_s: float, carrier_rel_ned_m: np.ndarray, sigma_m: float) -> None:
        """The vehicle stands on the deck at ``t_s`` [s]: the carrier's reference point is
        ``carrier_rel_ned_m`` [m] from the vehicle, to ``sigma_m`` [m] per axis, its height
        included (a vehicle standing on the deck is at the deck's height, however far its GNSS
        height is off). That error is one and the same for as long as the vehicle stands there,
        so repeating it tells nothing new: it is fused only as far as it brings the carrier's
        standard deviation on each axis down to ``sigma_m``, never below."""
        fix = MarkerFix(float(t_s), np.asarray(carrier_rel_ned_m, dtype=float), np.diag([sigma_m ** 2] * 3))
        self._add(_Event(self._key(t_s, _MARKER), marker=fix, seated=True))

    # --- output -----------------------------------------------------------------------------

    def estimate(self) -> RelativeEstimate:
        """The estimate at the newest tick (NaN before the first)."""
        self._catch_up()
        x, p, prm = self._x, self._p, self.params
        sigma = float(math.sqrt(max(float(np.max(np.linalg.eigvalsh(p[kalman.C_, kalman.C_]))), 0.0)))
        own = self._own[-1] if self._own else OwnSample(math.nan, np.full(3, math.nan), np.full(3, math.nan))
        now = own.t_s
        moving = x[kalman.W_] + x[kalman.D_]  # the carrier's velocity in the passenger's frame (its own plus the drift)
        covariance = p.copy()
        covariance.flags.writeable = False  # the estimate is a record: its readers (the flight data's thread) share it
        return RelativeEstimate(
            t_s=now, position_ned_m=x[kalman.C_] - own.position_ned_m, velocity_ned_m_s=moving - own.velocity_ned_m_s,
            bias_ned_m=x[kalman.B_].copy(), covariance=covariance, position_sigma_m=sigma,
            converged=bool(self._own) and sigma < prm.converged_sigma_m,
            since_marker_s=now - self._marker_t_s if self._own else math.inf, counts=self.counts(),
            carrier_position_ned_m=x[kalman.C_].copy(), carrier_velocity_ned_m_s=moving)

    def counts(self) -> Counts:
        """Measurements fused and rejected so far (each counted once, by its latest fusion)."""
        return Counts({k: self._fused[k] for k in KINDS}, dict(self._rejected), self._too_old, self._too_new,
                      self._fused[_RESET], self._fused[_OFF_DECK])

    # --- the history --------------------------------------------------------------------------

    def _key(self, t_s: float, rank: int) -> tuple[float, int, int]:
        if not math.isfinite(t_s):
            raise ValueError(f"a measurement time must be finite, got {t_s!r}")
        self._seq += 1
        return (float(t_s), rank, self._seq)

    def _add(self, event: _Event) -> None:
        base = self._snapshots[0].key if self._snapshots else None
        if base is None or event.key < base:
            self._too_old += 1  # before the first tick or older than the history
            return
        if event.t_s > self._own[-1].t_s + self.params.history_s:
            self._too_new += 1  # a clock that disagrees with the passenger's
            return
        self._insert(event)

    def _insert(self, event: _Event) -> None:
        bisect.insort(self._events, event, key=lambda e: e.key)
        if self._done is not None and event.key < self._done:
            self._replay_from = event.key if self._replay_from is None else min(self._replay_from, event.key)

    def _catch_up(self) -> None:
        """Bring the state to the newest tick: replay from before an out-of-order event, then fuse
        every event up to that tick in time order."""
        if not self._own:
            return
        if self._replay_from is not None:
            i = bisect.bisect_left(self._snapshots, self._replay_from, key=lambda s: s.key) - 1
            snap = self._snapshots[i]  # i >= 0: _add drops events older than the first snapshot
            del self._snapshots[i + 1:]
            self._x, self._p, self._marker_t_s, self._rejected_since_s = snap.x, snap.p, snap.marker_t_s, snap.rejected_since_s
            self._accel = snap.accel
            self._t_s, self._done, self._replay_from = snap.key[0], snap.key, None
        start = 0 if self._done is None else bisect.bisect_right(self._events, self._done, key=lambda e: e.key)
        now = self._own[-1].t_s
        for e in self._events[start:]:
            if e.t_s > now:
                break  # a measurement stamped after the newest tick waits for it
            self._fuse(e)
            self._done = e.key

    def _prune(self) -> None:
        """Forget what is older than ``history_s`` before the newest tick, keeping the newest
        snapshot before that as the base a late measurement replays from."""
        horizon = self._own[-1].t_s - self.params.history_s
        i = bisect.bisect_right(self._snapshots, horizon, key=lambda s: s.key[0]) - 1
        if i <= 0:
            return
        base = self._snapshots[i].key
        del self._snapshots[:i]
        del self._events[:bisect.bisect_left(self._events, base, key=lambda e: e.key)]
        k = bisect.bisect_left(self._own, base[0], key=lambda o: o.t_s)
        del self._own[:max(k - 1, 0)]  # keep one before the base: the GNSS difference interpolates

    # --- one event --------------------------------------------------------------------------

    def _fuse(self, e: _Event) -> None:
        self._predict_to(e.t_s)
        for kind, ok in e.outcome.items():  # a replay: this measurement's earlier fusion no longer counts
            (self._fused if ok else self._rejected)[kind] -= 1
        e.outcome = {}
        if e.tick is not None:
            self._snapshots.append(_Snapshot(e.key, self._x, self._p, self._marker_t_s, self._rejected_since_s, self._accel))
        elif e.marker is not None and e.seated:
            r = self._seated_noise(float(e.marker.covariance_ned_m2[0, 0]))
            if r is not None:
                z = np.asarray(e.marker.deck_rel_ned_m, dtype=float) + self._own_at(e.t_s).position_ned_m
                e.outcome["seated"] = self._update(z, kalman.H_MARKER, r)
        elif e.marker is not None:
            m = e.marker
            z = np.asarray(m.deck_rel_ned_m, dtype=float) + self._own_at(e.t_s).position_ned_m
            r = np.asarray(m.covariance_ned_m2, dtype=float) + kalman.I3 * self.params.marker_model_sigma_m ** 2
            e.outcome["marker"] = self._update(z, kalman.H_MARKER, r)
            if not e.outcome["marker"]:
                self._rejected_since_s = min(self._rejected_since_s, e.t_s)
                if e.t_s - self._rejected_since_s >= self.params.marker_reset_s:
                    self._p = self._prior()  # the deck moved as the model did not expect: start afresh from here
                    e.outcome[_RESET] = True
                    e.outcome["marker"] = self._update(z, kalman.H_MARKER, r)
            if e.outcome["marker"]:
                self._marker_t_s = max(self._marker_t_s, e.t_s)
                self._rejected_since_s = math.inf
        elif e.range is not None:
            self._fuse_range(e)
        elif e.fix is not None:
            prm = self.params
            z_p = np.asarray(e.fix.position_ned_m, dtype=float)
            z_v = np.asarray(e.fix.velocity_ned_m_s, dtype=float)
            e.outcome["gnss_position"] = self._update(z_p, kalman.H_GNSS_POSITION,
                                                      np.diag(self._per_axis(prm.gnss_position_sigma_m) ** 2))
            e.outcome["gnss_velocity"] = self._update(z_v, kalman.H_GNSS_VELOCITY,
                                                      kalman.I3 * prm.gnss_velocity_sigma_m_s ** 2)
            a = e.fix.acceleration_ned_m_s2
            self._accel = np.zeros(3) if a is None or not np.all(np.isfinite(a)) else np.asarray(a, dtype=float).copy()
        for kind, ok in e.outcome.items():
            (self._fused if ok else self._rejected)[kind] += 1

    def _fuse_range(self, e: _Event) -> None:
        """A range's event: off the deck by the estimate (the vehicle's horizontal place at the
        capture against the deck's centre, beyond its radius less the margin) it is not fused;
        over it, the reference point's height is the vehicle's own height then plus the range less
        the deck's top's offset, through the range's gate."""
        r = e.range
        assert r is not None
        own = self._own_at(e.t_s).position_ned_m
        top = np.asarray(r.deck_top_ned_m, dtype=float)
        off = self._x[kalman.C_][:2] + top[:2] - own[:2]  # [m] the deck's centre from the vehicle, horizontally
        if float(np.hypot(*off)) > r.deck_radius_m - self.params.range_deck_margin_m:
            e.outcome[_OFF_DECK] = True
            return
        z = np.array([own[2] + r.range_m - top[2]])
        u = kalman.update(self._x, self._p, z, H_HEIGHT, np.array([[r.sigma_m ** 2]]), self.params.range_gate_nis)
        self._x, self._p = u.x, u.p
        e.outcome["range"] = u.accepted

    def _predict_to(self, t_s: float) -> None:
        if self._t_s == -math.inf:
            self._t_s = t_s  # the first tick: the prior holds there
            return
        dt = t_s - self._t_s
        if dt <= 0.0:
            return
        model = self._models.get(dt)
        if model is None:  # the steps repeat (the tick's, the sensors' periods): computed once each
            prm = self.params
            if len(self._models) > 256:
                self._models.clear()
            accel = np.array([1.0, 1.0, prm.accel_vertical_factor]) * prm.accel_noise_m_s2
            model = self._models[dt] = (kalman.transition(dt, prm.bias_tau_s, prm.own_drift_tau_s),
                                        kalman.process_noise(dt, accel, self._per_axis(prm.bias_sigma_m),
                                                             prm.bias_tau_s, self._per_axis(prm.own_drift_sigma_m_s),
                                                             prm.own_drift_tau_s))
        step = kalman.input_step(dt, self._accel) if np.any(self._accel) else None
        self._x, self._p = kalman.predict(self._x, self._p, *model, step)
        self._t_s = t_s

    def _seated_noise(self, variance_m2: float) -> np.ndarray | None:
        """The seated measurement's noise covariance that brings the carrier's variance per axis
        down to ``variance_m2`` [m^2] and no lower (the information it lacks for that, per axis;
        an axis already there: unmeasured), or None: every axis is there already."""
        prior = np.diag(self._p)[kalman.C_]
        if not np.any(prior > variance_m2 * 1.0001):
            return None
        lack = 1.0 / variance_m2 - 1.0 / prior  # [1/m^2] the information missing per axis
        return np.diag(np.where(lack > 1e-12, 1.0 / np.maximum(lack, 1e-12), UNKNOWN_M ** 2))

    def _update(self, z: np.ndarray, h: np.ndarray, r: np.ndarray) -> bool:
        u = kalman.update(self._x, self._p, z, h, r, self.params.gate_nis)
        self._x, self._p = u.x, u.p
        return u.accepted

    def _own_at(self, t_s: float) -> OwnSample:
        """The passenger's own estimate at ``t_s`` [s], linear between the ticks round it."""
        own = self._own
        i = bisect.bisect_left(own, t_s, key=lambda o: o.t_s)
        if i < len(own) and own[i].t_s == t_s:
            return own[i]
        if i == 0:
            return own[0]
        if i == len(own):
            return own[-1]
        a, b = own[i - 1], own[i]
        w = (t_s - a.t_s) / (b.t_s - a.t_s)
        return OwnSample(t_s, a.position_ned_m + w * (b.position_ned_m - a.position_ned_m),
                         a.velocity_ned_m_s + w * (b.velocity_ned_m_s - a.velocity_ned_m_s))
