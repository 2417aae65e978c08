"""The deck in the passenger's own frame (pure; ``[relnav]`` enabled): the relative estimator
(:class:`mission.relnav.estimator.RelativeEstimator`) run inside the passenger's step, and the
carrier's state moved into the passenger's GNSS frame.

Each tick, in this order: the carrier's state, if it is a new sample (stamped ``t - age``, its
measurement time), and this tick's marker readings
(:class:`~mission.phases.measurements.RelativePosition`, by capture time: ``Measurements.arrived``)
and downward ranges (:class:`~mission.phases.measurements.DownwardRange`, the feed ``rangefinder``:
the deck's top, the seat, that far under the vehicle while over the deck; only in the phases the
caller names: :data:`mission.phases.phase.RANGED`) are handed to the estimator; then the vehicle's own sample (its position and velocity as the
autopilot reports them, at their sample time) moves it on. The marker lies on the deck,
``gates.marker_offset_ned_m`` from the carrier's reference point (``vision.marker_offset_ned_m``:
by default the dock point; a hover ride's configuration puts it on the deck under the hover point,
in the camera's view while riding); the estimator tracks the carrier's reference point. The phases then see the carrier where the estimate has it (the carrier's position and
velocity in the passenger's frame, the filter's state: the raw fixes' noise filtered, the marker
pinning it near the deck, one estimate with no switch between sources), less the **pending**
part of the estimate's jumps (its change beyond its own velocity's), let through at most at
``relnav.correction_rate_m_s``: the first marker moves the carrier by up to metres (the
GNSS-frame bias), and the phases' references would otherwise see the deck jump in one tick. Far
away (no marker) the bias estimate stays near its prior's mean (zero), or where the last marker
left it, so the carrier's state is used nearly as it comes. Frames: local NED [m], [m/s]; times
[s] on the caller's clock. docs/relnav.md, "In the phases".
"""
from __future__ import annotations

import math

from mission.core.records import replace

import numpy as np

from mission.passenger.inputs import VehicleReport
from mission.phases.measurements import DownwardRange, Measurements, RelativePosition
from mission.phases.types import CarrierObs, RelativeView, RelnavGates
from mission.relnav.estimator import RelativeEstimator
from mission.relnav.kalman import B_
from mission.relnav.inputs import CarrierFix, EstimatorInput, MarkerFix, OwnSample, RangeFix, RelativeEstimate, Seated


HANDED_KEPT = 1000  # inputs kept for the next view while none is made (the vehicle not heard yet): ~10 s of them


class RelativeDeck:
    """The estimator and the correction it drives, for the gates ``gates`` (``[relnav]``); the
    marker lies ``gates.marker_offset_ned_m`` [m] NED from the carrier's reference point; the dock
    point, where the vehicle sits when docked, ``dock_offset_ned_m`` [m] NED from it
    (``mission.dock_offset_ned_m``); the seat, where the vehicle stands before take-off,
    ``seat_offset_ned_m`` [m] NED from it (None: the dock point, as on a deck ride; a hover ride's
    is the dock point's horizontal place on the deck, at the reference point's height:
    :func:`seat_offset`), which is also the deck's top and centre a downward range measures
    (the feed ``rangefinder``: :class:`~mission.phases.measurements.DownwardRange`)."""

    def __init__(self, gates: RelnavGates, dock_offset_ned_m: np.ndarray, seat_offset_ned_m: np.ndarray | None = None) -> None:
        self.gates = gates
        self.dock_offset = np.asarray(dock_offset_ned_m, dtype=float)
        self.seat_offset = self.dock_offset if seat_offset_ned_m is None else np.asarray(seat_offset_ned_m, dtype=float)
        self.marker_offset = np.asarray(gates.marker_offset_ned_m, dtype=float)
        self.estimator = RelativeEstimator(gates.params)
        self.fix_t_s = -np.inf  # [s] the newest carrier sample handed to the estimator
        self.fix_stamp_s: float | None = None  # [s] ... and its time on the carrier's clock (None: unknown)
        self.own_t_s = -np.inf  # [s] the newest own sample
        self.last: tuple[np.ndarray, np.ndarray] | None = None  # the last tick's carrier [m] and velocity [m/s], before pending
        self.pending = np.zeros(3)  # [m] NED, the part of the estimate's jumps not yet let through
        self.velocity: np.ndarray | None = None  # [m/s] NED, the deck's velocity as last shown to the phases
        self.accel = np.zeros(3)  # [m/s^2] NED, the rate of that velocity low-passed (gates.carrier_accel_tau_s)
        self.t_s: float | None = None  # [s] the last tick's time
        self.refused = 0  # readings not fused: no stated sigma, or a non-finite time, offset or sigma
        self.unranged = 0  # downward ranges not handed to the estimator: they arrived outside the phases that fuse them
        self.handed: list[EstimatorInput] = []  # what the estimator was handed since the last view (the view's inputs)

    def observe(self, t_s: float, vehicle: VehicleReport | None, carrier: CarrierObs | None,
                measurements: Measurements, on_deck: bool = False, ranged: bool = True) -> tuple[CarrierObs | None, RelativeView | None]:
        """This tick's readings in; the carrier's state in the passenger's frame and the
        estimate's view out (None until the vehicle's first sample). ``on_deck``: the vehicle
        stands on the deck (before take-off: the paper's Assumption 2), on its seat:
        :meth:`RelativeEstimator.seated` with ``relnav.seated_sigma_m``. ``ranged``: this tick's
        downward ranges are handed to the estimator (else dropped and counted in ``unranged``;
        the caller decides by phase: :data:`mission.phases.phase.RANGED`)."""
        est = self.estimator
        sent = None if carrier is None else _sent_acceleration(carrier)
        if carrier is not None and self._new_fix(t_s, carrier):
            self.fix_t_s, self.fix_stamp_s = t_s - carrier.age_s, carrier.stamp_s
            self._hand(CarrierFix(self.fix_t_s, np.asarray(carrier.position_ned_m, float),
                                  np.asarray(carrier.velocity_ned_m_s, float), sent))
        for m in measurements.arrived(RelativePosition):
            if _usable(m) and m.sigma_m is not None:  # the carrier's reference point is marker_offset from the marker
                self._hand(MarkerFix.isotropic(m.capture_t_s, np.asarray(m.offset_ned_m, float) - self.marker_offset, m.sigma_m))
            else:
                self.refused += 1
        for r in measurements.arrived(DownwardRange):  # the deck's top is the seat: the deck's centre, at its height
            if not ranged:
                self.unranged += 1
            elif _usable_range(r) and r.sigma_m is not None:
                self._hand(RangeFix(r.capture_t_s, r.range_m, r.sigma_m, self.seat_offset, self.gates.deck_radius_m))
            else:
                self.refused += 1
        if on_deck and vehicle is not None and vehicle.sample_t_s is not None and vehicle.sample_t_s > self.own_t_s:
            self._hand(Seated(vehicle.sample_t_s, -self.seat_offset, self.gates.seated_sigma_m))
        if vehicle is None or vehicle.position_ned_m is None or vehicle.velocity_ned_m_s is None:
            return carrier, None
        sample_t = vehicle.sample_t_s if vehicle.sample_t_s is not None else t_s
        pos, vel = np.asarray(vehicle.position_ned_m, float), np.asarray(vehicle.velocity_ned_m_s, float)
        if sample_t > self.own_t_s and np.all(np.isfinite(pos)) and np.all(np.isfinite(vel)):
            self.own_t_s = sample_t
            e = self._hand(OwnSample(sample_t, pos, vel))
            assert e is not None  # an own sample ticks the estimator
        elif self.own_t_s == -np.inf:
            return carrier, None
        else:
            e = est.estimate()
        bias = np.asarray(e.bias_ned_m, float)
        if carrier is None or e.counts.fused["gnss_position"] == 0:  # not in the passenger's frame before one fix is fused
            return None, self._view(e, bias)
        # the carrier's state filtered (GNSS far away, the marker near: one estimate, no switch),
        # moved on from the vehicle's sample to now; its velocity is the carrier's own, not the vehicle's
        velocity = np.asarray(e.carrier_velocity_ned_m_s, float)
        now = np.asarray(e.carrier_position_ned_m, float) + velocity * max(t_s - sample_t, 0.0)
        if self.last is None or on_deck:  # standing on the deck, nothing flies on it: no slew
            self.pending = np.zeros(3)
        else:
            dt = max(t_s - (self.t_s if self.t_s is not None else t_s), 0.0)
            was, was_v = self.last
            self.pending = self.pending - (now - (was + 0.5 * (was_v + velocity) * dt))  # jumps, let through at the rate
            size = float(np.linalg.norm(self.pending))
            step = self.gates.correction_rate_m_s * dt
            self.pending = np.zeros(3) if size <= step else self.pending * (1.0 - step / size)
        self.last = (now, velocity)
        dt = max(t_s - self.t_s, 0.0) if self.t_s is not None else 0.0
        before = self.velocity
        shown = self._slewed(velocity, dt_s=dt, on_deck=on_deck, sent=sent)
        accel = self._acceleration(before, shown, dt, on_deck)
        self.t_s = t_s
        now = now + self.pending
        # the state handed on is the carrier's at its sample's time, as a fix's is (its readers move it on
        # over age_s): the estimate's now moved back, with the acceleration it sent when it sent one (the
        # estimate's velocity already carries it through the fix's latency)
        age, a = carrier.age_s, (np.zeros(3) if sent is None else sent)
        # its law runs in its own frame (carrier.p3_frame "own"): a prediction by it starts from where it says it
        # is, not from the passenger's frame, which is off by the two GNSS biases (2 m at 8-10 m from the target
        # turned the law's course by ~0.2 rad: the ride fed forward 0.2-0.25 m/s across the carrier's velocity);
        # with "passenger" its law runs in the guards' frame (its position less the bias it heard), as here
        return replace(carrier, position_ned_m=now - shown * age + 0.5 * a * age * age, velocity_ned_m_s=shown - a * age,
                       own_frame_position_ned_m=np.asarray(carrier.position_ned_m, float) if self.gates.carrier_law_own_frame
                       else None), \
            self._view(e, bias, accel)

    def _new_fix(self, t_s: float, carrier: CarrierObs) -> bool:
        """Whether ``carrier`` is a measurement not yet handed to the estimator: by another stamp on
        the carrier's own clock when the feed gives it (another, not only a later one: a carrier
        clock that stepped back must not silence its fixes), else by a later measurement time on
        ours (``t_s - age_s`` [s]). The same measurement comes again every tick until the next, and a
        carrier publishing at 30 Hz sends each 10 Hz GNSS fix three times; on our clock its time
        moves by microseconds to milliseconds as the clock offset is corrected, so by that time
        alone, on real PX4 over half the fixes handed were such repeats, each fused as a new
        measurement (docs/relnav.md, "Replaying a flight's estimator")."""
        if carrier.stamp_s is not None and self.fix_stamp_s is not None:
            return carrier.stamp_s != self.fix_stamp_s
        return t_s - carrier.age_s > self.fix_t_s

    def _hand(self, item: EstimatorInput) -> RelativeEstimate | None:
        """Hand ``item`` to the estimator (:func:`hand`: an own sample ticks it and gives the estimate,
        a measurement waits for the next tick, None) and keep it for the next view's ``inputs`` (the
        newest :data:`HANDED_KEPT` of them, while no view is made)."""
        self.handed.append(item)
        if len(self.handed) > HANDED_KEPT:
            del self.handed[0]
        return hand(self.estimator, item)

    def _acceleration(self, before: np.ndarray | None, shown: np.ndarray, dt_s: float, on_deck: bool) -> np.ndarray | None:
        """The carrier's acceleration [m/s^2] NED as the estimate shows it: the rate of the velocity
        shown to the phases (``before`` the last tick's, ``shown`` this one's, ``dt_s`` [s] apart),
        low-passed with ``gates.carrier_accel_tau_s`` (exact first-order step); None when that is 0.
        The shown velocity changes at most at the carrier's acceleration limit (and the catch-up's
        share, :meth:`_slewed`), and this no faster. Zero standing on the deck (nothing rides it) and until a velocity was shown."""
        tau = self.gates.carrier_accel_tau_s
        if tau <= 0:
            return None
        if on_deck or before is None:
            self.accel = np.zeros(3)
        elif dt_s > 0:
            rate = (shown - before) / dt_s
            self.accel = self.accel + (1.0 - math.exp(-dt_s / tau)) * (rate - self.accel)
        return self.accel.copy()

    def _slewed(self, velocity: np.ndarray, dt_s: float, on_deck: bool, sent: np.ndarray | None = None) -> np.ndarray:
        """The deck's velocity [m/s] shown to the phases: the filter's, changing by at most the
        carrier's acceleration limit (``gates.carrier_accel_m_s2``) over ``dt_s`` [s], plus
        ``gates.deck_velocity_catch_up_per_s`` times how far it is behind. The carrier does not
        change its velocity faster in its normal driving, so what is faster is the filter's noise
        (each marker moves it, ~0.06 m/s a tick at the 95th percentile while riding), which the
        riding command would carry into the relative input at the separation. A lag of decimetres
        a second is no noise: behind a carrier pulling away at its limit, a velocity limited to
        that limit never catches up (0.2-0.7 m/s behind, the rider 0.5-0.65 m off its dock point
        2 s into the ride), and a carrier stopping dead at its P3 guard was followed down at
        1 m/s^2 (the rider 0.8-1 m past its dock point). With the acceleration the carrier
        measured and ``sent`` [m/s^2] NED the limit is round the change it makes (that is motion, not
        noise: at the limit itself the shown velocity could not take a single correction)."""
        limit = self.gates.carrier_accel_m_s2
        if self.velocity is None or limit is None or on_deck:
            self.velocity = velocity.copy()
            return self.velocity
        expected = self.velocity if sent is None else self.velocity + sent * dt_s
        change = velocity - expected
        size = float(np.linalg.norm(change))
        step = (limit + self.gates.deck_velocity_catch_up_per_s * size) * dt_s
        self.velocity = velocity.copy() if size <= step else expected + change * (step / size)
        return self.velocity

    def _view(self, e: RelativeEstimate, bias: np.ndarray, accel: np.ndarray | None = None) -> RelativeView:
        inputs, self.handed = tuple(self.handed), []
        return RelativeView(position_ned_m=np.asarray(e.position_ned_m, float), bias_ned_m=bias,
                            pending_ned_m=self.pending.copy(), position_sigma_m=e.position_sigma_m,
                            converged=e.converged, since_marker_s=e.since_marker_s, estimate=e,
                            carrier_accel_ned_m_s2=accel, inputs=inputs)


def shared_bias(view: RelativeView | None) -> tuple[np.ndarray, float] | None:
    """What the passenger's status shares of the frames' bias (:class:`mission.bus.wire.PassengerStatus`):
    ``bias_ned_m`` [m] NED the carrier's GNSS frame minus the passenger's and ``bias_sigma_m`` [m]
    the square root of the bias block's largest eigenvalue, while ``view`` (``[relnav]`` enabled)
    has converged and has its covariance; else None (nothing shared, no relnav: the status's bytes
    unchanged). The carrier's P3 guard may run in the passenger's frame on it
    (:mod:`mission.carrier.frames`)."""
    if view is None or not view.converged or view.estimate is None:
        return None
    bias = np.asarray(view.bias_ned_m, dtype=float)
    block = np.asarray(view.estimate.covariance, dtype=float)[B_, B_]
    sigma = math.sqrt(max(float(np.linalg.eigvalsh(0.5 * (block + block.T))[-1]), 0.0))
    if not (np.all(np.isfinite(bias)) and math.isfinite(sigma)):
        return None
    return bias, sigma


def hand(estimator: RelativeEstimator, item: EstimatorInput) -> RelativeEstimate | None:
    """One input to ``estimator`` by its kind: an own sample ticks it (and returns the estimate),
    the rest wait in its history for the next tick (None). The one place an input record becomes
    a call, so a flight log's inputs replay as the flight handed them."""
    if isinstance(item, OwnSample):
        return estimator.tick(item)
    if isinstance(item, CarrierFix):
        estimator.carrier(item)
    elif isinstance(item, MarkerFix):
        estimator.marker(item)
    elif isinstance(item, RangeFix):
        estimator.range(item)
    else:
        estimator.seated(item.t_s, item.carrier_rel_ned_m, item.sigma_m)
    return None


def _sent_acceleration(carrier: CarrierObs) -> np.ndarray | None:
    """The acceleration [m/s^2] NED the carrier measured and sent with its state, None if it sent
    none or one that is not finite."""
    a = carrier.acceleration_ned_m_s2
    if a is None:
        return None
    a = np.asarray(a, dtype=float)
    return a if a.shape == (3,) and np.all(np.isfinite(a)) else None


def _usable(m: RelativePosition) -> bool:
    """A reading the estimator can fuse: a finite capture time [s], a finite offset [m] and a
    stated, finite, positive sigma [m]. Anything else (a faulty or hostile feed) is refused and
    counted, never raised into the loop."""
    return (m.sigma_m is not None and math.isfinite(m.sigma_m) and m.sigma_m > 0 and math.isfinite(m.capture_t_s)
            and bool(np.all(np.isfinite(np.asarray(m.offset_ned_m, float)))))


def _usable_range(r: DownwardRange) -> bool:
    """A range the estimator can fuse: a finite capture time [s], a finite, non-negative range [m]
    and a stated, finite, positive sigma [m] (else refused and counted, as :func:`_usable`)."""
    return (r.sigma_m is not None and math.isfinite(r.sigma_m) and r.sigma_m > 0 and math.isfinite(r.capture_t_s)
            and math.isfinite(r.range_m) and r.range_m >= 0)


def seat_offset(dock_offset_ned_m: np.ndarray, deck_ride: bool) -> np.ndarray:
    """[m] NED from the carrier's reference point, where the passenger stands on the deck before
    take-off: on a deck ride the dock point; on a hover ride the dock point's horizontal place at
    the reference point's height (the deck the hover ride takes off from and the altitude floor
    stands on: ``mission.phases.flying``)."""
    dock = np.asarray(dock_offset_ned_m, dtype=float)
    return dock.copy() if deck_ride else np.array([dock[0], dock[1], 0.0])
