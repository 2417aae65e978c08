"""What the relative estimator reads and what it reports (pure records, SI units, NED axes).

Frames. Every position is in local NED axes (north, east, down) [m]; what differs is the origin
each vehicle's GNSS puts under it:

- the **passenger's GNSS frame**: where the passenger's own estimate (PX4's local position) says
  it is; it errs from the truth by the passenger's GNSS error;
- the **carrier's GNSS frame**: where the carrier's published state says the carrier is; it errs
  by the carrier's GNSS error, independent of the passenger's;
- the **marker** needs no frame origin: the vision system measures the deck from the vehicle
  (deck minus vehicle) in NED axes, a vector that no GNSS error touches.

So the carrier's published position minus the passenger's own is the true relative position plus
the bias between the two GNSS frames, ``b = e_carrier - e_passenger`` [m]; velocities share no
bias (a frame offset does not move). Times are on the passenger's clock [s].
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class OwnSample:
    """The passenger's own estimate at ``t_s`` [s]: ``position_ned_m`` (3,) [m] in the passenger's
    GNSS frame and ``velocity_ned_m_s`` (3,) [m/s], as its autopilot reports them."""

    t_s: float
    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray


@dataclass(frozen=True)
class CarrierFix:
    """The carrier's reported GNSS state, measured at ``t_s`` [s] (its stamp, not its arrival):
    ``position_ned_m`` (3,) [m] in the carrier's GNSS frame (of the deck's reference point) and
    ``velocity_ned_m_s`` (3,) [m/s]; ``acceleration_ned_m_s2`` (3,) [m/s^2]: the acceleration the
    carrier measured with its own inertial state and sent beside the fix (newer than the fix by its
    latency), or None (it sent none)."""

    t_s: float
    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    acceleration_ned_m_s2: np.ndarray | None = None


class MarkerObservation(Protocol):
    """A marker's measurement of the deck from the vehicle. ``mission.vision.measurement``'s
    ``RelativeMeasurement`` is one (structurally: the estimator reads only these three).

    capture_t_s: when the frame was exposed [s] (on the passenger's clock);
    deck_rel_ned_m (3,): what the estimator tracks (the carrier's reference point) minus the
    vehicle's reference point, NED axes [m] (a deck marker elsewhere on the carrier is moved onto
    it by its caller);
    covariance_ned_m2 (3, 3): its covariance [m^2]."""

    @property
    def capture_t_s(self) -> float: ...

    @property
    def deck_rel_ned_m(self) -> np.ndarray: ...

    @property
    def covariance_ned_m2(self) -> np.ndarray: ...


@dataclass(frozen=True)
class MarkerFix:
    """A plain :class:`MarkerObservation` (for a source without vision's full record)."""

    capture_t_s: float
    deck_rel_ned_m: np.ndarray
    covariance_ned_m2: np.ndarray

    @classmethod
    def isotropic(cls, capture_t_s: float, deck_rel_ned_m: np.ndarray, sigma_m: float) -> MarkerFix:
        """One with the same standard deviation ``sigma_m`` [m] on every axis."""
        return cls(capture_t_s, np.asarray(deck_rel_ned_m, dtype=float), np.eye(3) * sigma_m ** 2)


@dataclass(frozen=True)
class RangeFix:
    """A downward range captured at ``t_s`` [s]: ``range_m`` [m] from the vehicle's reference point
    straight down (NED down) to the surface below it, to ``sigma_m`` [m]; the deck's top is
    ``deck_top_ned_m`` (3,) [m] NED from the carrier's reference point (its centre: the seat) and
    ``deck_radius_m`` [m] its radius. Over the deck (by the estimate) the deck's top is the
    vehicle's own position at ``t_s`` plus the range straight down."""

    t_s: float
    range_m: float
    sigma_m: float
    deck_top_ned_m: np.ndarray
    deck_radius_m: float


@dataclass(frozen=True)
class Seated:
    """The vehicle standing on the deck at ``t_s`` [s]: the carrier's reference point is
    ``carrier_rel_ned_m`` (3,) [m] NED from the vehicle, to ``sigma_m`` [m] per axis
    (:meth:`mission.relnav.estimator.RelativeEstimator.seated`'s arguments, as one record)."""

    t_s: float
    carrier_rel_ned_m: np.ndarray
    sigma_m: float


# What the estimator is handed, one record per call (its inputs, in the order handed: a flight log
# of them replays the estimator exactly)
EstimatorInput = OwnSample | CarrierFix | MarkerFix | RangeFix | Seated


@dataclass(frozen=True)
class Counts:
    """Measurements fused and rejected by the gate, by kind (``marker``, ``gnss_position``,
    ``gnss_velocity``, ``seated``, ``range``); ``too_old``: measurements older than the history, ``too_new``: stamped
    more than the history after the newest tick (both dropped unfused); ``resets``: re-initialisations of
    the uncertainty by a run of rejected markers (``relnav.marker_reset_s``); ``off_deck``: ranges not
    fused because the estimate had the vehicle off the deck (they measured the ground)."""

    fused: dict[str, int]
    rejected: dict[str, int]
    too_old: int
    too_new: int = 0
    resets: int = 0
    off_deck: int = 0


@dataclass(frozen=True)
class RelativeEstimate:
    """The estimate at ``t_s`` [s].

    position_ned_m (3,): the carrier's reference point minus the vehicle's [m], NED axes (the
    truth's estimate: what the marker measures, not what the GNSS difference says);
    velocity_ned_m_s (3,): its rate, the carrier's velocity in the passenger's frame (its own plus
    the drift of the passenger's estimate) minus the vehicle's [m/s];
    bias_ned_m (3,): the carrier's GNSS frame minus the passenger's [m] (the GNSS difference
    minus the relative position);
    covariance (12, 12): the filter's, of its state (the carrier's reference point [m], its own
    velocity [m/s], the bias [m], the passenger's own drift rate [m/s]) in that order (the vehicle's
    own state is an input, known: the relative position's covariance is the carrier's; the
    relative velocity is the carrier's plus the drift, less the vehicle's); blocks in [m^2],
    [m^2/s^2], [m^2], [m^2/s^2] on the diagonal; a read-only copy;
    position_sigma_m: the position's largest standard deviation [m];
    converged: ``position_sigma_m`` is below the configured threshold;
    since_marker_s: time since the capture of the newest marker fused [s] (inf: none yet);
    counts: what was fused and rejected;
    carrier_position_ned_m (3,), carrier_velocity_ned_m_s (3,): the carrier's reference point
    [m] and velocity [m/s] in the passenger's GNSS frame (the filter's state: steady through the
    vehicle's own manoeuvres)."""

    t_s: float
    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    bias_ned_m: np.ndarray
    covariance: np.ndarray
    position_sigma_m: float
    converged: bool
    since_marker_s: float
    counts: Counts
    carrier_position_ned_m: np.ndarray
    carrier_velocity_ned_m_s: np.ndarray
