"""``[relnav]`` (the relative estimator of the deck from the passenger, :mod:`mission.relnav`) and
``[world]`` (the errors the simulated world adds to what the vehicles report of themselves: the
carrier's published GNSS state, the passenger's own GNSS bias). Part of the schema in
:mod:`mission.config.schema`; the models and the measurements are in docs/relnav.md.

``[world]`` is read only by the simulators (``sim/``), never by the controller: the controller
sees the errors only through what it is sent. Every error is off unless a configuration asks.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Literal

from pydantic import Field, model_validator

from mission.config.fields import Section
from mission.errors import ConfigError

if TYPE_CHECKING:
    from mission.relnav.estimator import RelnavParams


#: ``[relnav]``'s fields that tell the phases how to use the estimate (not the estimator's tuning).
PHASE_FIELDS = ("enabled", "marker_timeout_s", "descent_marker_timeout_s", "marker_memory_s", "search_s", "correction_rate_m_s", "seated_sigma_m",
                "pending_limit_m", "landing_target_rate_hz", "carrier_accel_tau_s", "velocity_slew_m_s2",
                "deck_velocity_catch_up_per_s")
FEED_FIELDS = ("range_sigma_m",)  # read by a flight's measurement feeds (mission.cli.rangefinder), not the estimator


class RelnavSection(Section):
    """The relative estimator's tuning: its models of the GNSS errors and of the marker, its gate;
    and whether and how the phases use its estimate (``enabled`` and the fields after it)."""

    enabled: bool = Field(False,
        description=("[-] the passenger's step runs the relative estimator on the carrier's state, its own and the "
                     "marker's readings (`mission.feeds`), and the phases fly the deck in the passenger's own frame "
                     "(the carrier's state less the estimated GNSS-frame bias); the descent below "
                     "`recovery.decision_height_m` then needs the marker in sight and the estimate converged"))
    marker_timeout_s: float = Field(0.5, gt=0, le=10,
        description="[s] the marker counts as in sight while its newest fused capture is no older than this")
    descent_marker_timeout_s: float = Field(0.25, gt=0, le=10,
        description=("[s] below the decision height the marker counts as lost once its newest fused capture is older "
                     "than this, and the vehicle climbs (at most `relnav.marker_timeout_s`; at least the camera's "
                     "latency and a frame or two: blind, the relative height drifts with the vehicle's own height "
                     "estimate, ~0.3 m/s with PX4's errors)"))
    marker_memory_s: float = Field(20.0, gt=0, le=600,
        description=("[s] HOLDOFF begins an approach only with a marker fused this recently; else it searches for "
                     "it over the deck at the holdoff height"))
    search_s: float = Field(10.0, gt=0, le=120,
        description=("[s] how long HOLDOFF searches over the deck for the marker before falling back, and how "
                     "long the descent holds its height with the marker lost before it goes around"))
    correction_rate_m_s: float = Field(0.5, gt=0, le=10,
        description=("[m/s] the fastest the bias correction applied to the carrier's state may move (a new "
                     "estimate of metres moves the deck smoothly, not in one tick)"))
    seated_sigma_m: float = Field(0.3, gt=0, le=10,
        description=("[m] before take-off the vehicle stands on the deck (Assumption 2): the estimator takes the "
                     "deck as straight under it, horizontally, to this standard deviation per axis (the same error "
                     "all the while it stands: the estimate is never made surer than this by it)"))
    pending_limit_m: float = Field(0.3, gt=0, le=10,
        description=("[m] HOLDOFF begins an approach, and JOIN settles into the ride, only once the part of the "
                     "estimate's jumps still held back (let through at `relnav.correction_rate_m_s`) is below this"))
    carrier_accel_tau_s: float = Field(0.0, ge=0, le=10,
        description=("[s] riding, the carrier's acceleration fed forward (when the carrier sends none) is the rate of "
                     "the estimate's carrier velocity (as the phases see it, slewed at the carrier's acceleration "
                     "limit), low-passed with this time constant, instead of its law's (`mission.carrier_accel_horizon_s`): "
                     "a carrier that does not drive its law (a PX4 rover at its own cruise speed, under the law's "
                     "`safety.carrier_max_speed_m_s`; one that stands a while before it moves off) is ridden as it "
                     "moves, not as the law says it should; 0: the law's"))
    velocity_slew_m_s2: float | None = Field(None, gt=0, le=50,
        description=("[m/s^2] the carrier's velocity the phases see (the estimate's) changes at most this fast: the "
                     "filter's noise (each marker moves it) is slewed away, the carrier cannot change its velocity "
                     "faster; unset: the law's limit `safety.carrier_max_accel_m_s2`. A carrier that does (the SIH "
                     "rover leaps from rest at ~2 m/s^2) needs its own, or the ride lags it"))
    landing_target_rate_hz: float = Field(0.0, ge=0, le=50,
        description=("[Hz] while the estimate is converged, the loop sends the vehicle the deck's landing point "
                     "(the dock point in its local NED frame: its own position plus the relative estimate) as "
                     "LANDING_TARGET this often, for PX4's own precision landing as a backstop (docs/px4-precland.md); "
                     "0: never"))

    deck_velocity_catch_up_per_s: float = Field(0.0, ge=0, le=100,
        description=("[1/s] the deck's velocity the phases see changes by at most the carrier's acceleration limit "
                     "(`safety.carrier_max_accel_m_s2`: the filter's noise, which the riding command would carry into "
                     "the separation, is faster) plus this times how far it is behind the filter's velocity: a lag "
                     "beyond the noise (a carrier pulling away at its limit from a lagging start, or braking "
                     "harder than it, at a P3 guard) is caught up; 0: the limit alone"))

    accel_noise_m_s2: float = Field(0.5, gt=0, le=50,
        description=("[m/s^2/sqrt(Hz)] square root of the spectral density of the white relative acceleration "
                     "driving the constant-velocity model (per axis)"))
    bias_sigma_m: float = Field(2.0, gt=0, le=100,
        description=("[m] standard deviation of the bias between the carrier's and the passenger's GNSS frames (per "
                     "horizontal axis)"))
    bias_tau_s: float = Field(300.0, gt=0, le=100_000,
        description="[s] correlation time of that bias (first-order Gauss-Markov)")
    vertical_factor: float = Field(1.5, ge=0.1, le=10,
        description="[-] the vertical bias and GNSS position noise over the horizontal ones")
    gnss_position_sigma_m: float = Field(0.35, gt=0, le=100,
        description=("[m] white noise of the GNSS relative position (the carrier's published position minus the "
                     "passenger's own, per horizontal axis)"))
    gnss_velocity_sigma_m_s: float = Field(0.3, gt=0, le=20,
        description="[m/s] white noise of the relative velocity (the carrier's published velocity minus the passenger's own)")
    initial_sigma_m: float = Field(100.0, gt=0, le=10_000,
        description="[m] the relative position's prior standard deviation before any measurement")
    initial_velocity_sigma_m_s: float = Field(10.0, gt=0, le=1_000,
        description="[m/s] the relative velocity's prior standard deviation before any measurement")
    gate_nis: float = Field(16.27, gt=0, le=10_000,
        description=("[-] a measurement whose normalised innovation squared exceeds this is rejected (16.27: "
                     "chi-square, 3 degrees of freedom, 0.999)"))
    marker_reset_s: float = Field(0.5, gt=0, le=60,
        description=("[s] markers rejected by the gate for this long in a row, none fused between (by capture time), "
                     "re-initialise the estimate's uncertainty to its prior, keeping the state, and the marker is fused "
                     "afresh: the deck moved as the model did not expect (a carrier braking hard, a frame's jump), and "
                     "the marker is the deck; a lone outlier among fused markers is still rejected"))
    marker_model_sigma_m: float = Field(0.0, ge=0, le=1,
        description=("[m] per axis, added in quadrature to each marker's own covariance (which holds the corners' "
                     "noise only): what the detector cannot know of (the vehicle's own position and attitude at the "
                     "capture, the capture's time). A marker the detector called a centimetre sure and 9 cm off "
                     "otherwise swings the deck's velocity by 0.5 m/s and the filter then rejects the good ones; "
                     "0: the detector's covariance alone"))
    history_s: float = Field(1.0, gt=0, le=30,
        description="[s] how far back a late measurement is still fused (replayed from its capture time)")
    converged_sigma_m: float = Field(0.1, gt=0, le=100,
        description="[m] the estimate counts as converged when its position's largest standard deviation is below this")
    own_drift_sigma_m_s: float = Field(0.0, ge=0, le=10,
        description=("[m/s] standard deviation of the rate at which the passenger's own position estimate drifts (its "
                     "autopilot's estimate error changing; per horizontal axis, down times `relnav.vertical_factor`), "
                     "a state of the filter: the deck moves at the carrier's velocity plus it in the passenger's "
                     "frame, the carrier's GNSS velocity sees the carrier's alone, so through a marker loss the deck "
                     "keeps the drift the marker showed (PX4 SITL's: "
                     "~0.09 m/s horizontally, ~0.18 m/s down); 0: no such state (the GNSS velocity is the deck's)"))
    own_drift_tau_s: float = Field(1.0, gt=0, le=600,
        description="[s] correlation time of that drift rate (first-order Gauss-Markov)")
    accel_vertical_factor: float = Field(1.0, ge=0.01, le=10,
        description=("[-] the carrier's vertical acceleration noise over `relnav.accel_noise_m_s2` (a ground "
                     "carrier on flat ground: small, so the marker's vertical rate is read as the passenger's own "
                     "drift, `relnav.own_drift_sigma_m_s`, not as the carrier climbing)"))
    range_gate_nis: float = Field(10.83, gt=0, le=10_000,
        description=("[-] a downward range (the feed `rangefinder`) whose normalised innovation squared exceeds this is "
                     "rejected (10.83: chi-square, 1 degree of freedom, 0.999)"))
    range_deck_margin_m: float = Field(0.1, ge=0, le=10,
        description=("[m] a downward range is fused (the deck's height from the vehicle's own height plus it) only "
                     "while the estimate has the vehicle within `recovery.deck_radius_m` less this of the deck's "
                     "centre, horizontally: else it measured the ground (counted `off_deck`)"))
    range_sigma_m: float = Field(0.05, gt=0, le=5,
        description=("[m] a flight's downward range's standard deviation when the vehicle does not state it "
                     "(the feed `rangefinder`: DISTANCE_SENSOR's covariance 0 or 255, unknown; PX4 sends 0 for a "
                     "driver that sets no variance)"))

    @model_validator(mode="after")
    def _descent_timeout(self) -> RelnavSection:
        if self.descent_marker_timeout_s > self.marker_timeout_s:
            raise ConfigError("relnav.descent_marker_timeout_s", self.descent_marker_timeout_s,
                              f"must be <= relnav.marker_timeout_s = {self.marker_timeout_s:g} (the descent needs the "
                              "marker at least as recent as the gate does)")
        return self

    def params(self) -> RelnavParams:
        from mission.relnav.estimator import RelnavParams

        return RelnavParams(**{name: getattr(self, name) for name in type(self).model_fields if name not in PHASE_FIELDS + FEED_FIELDS})


class CarrierGnssSection(Section):
    """The error of the carrier's published GNSS state, as the simulated world adds it (off by default)."""

    enabled: bool = Field(False, description="[-] the simulated carrier publishes an erring GNSS state")
    mode: Literal["standalone", "rtk"] = Field("standalone",
        description=("[-] `standalone`: a drifting metre-level bias; `rtk`: moving-base RTK, centimetres with "
                     "occasional float fallbacks"))
    bias_sigma_m: float = Field(1.5, ge=0, le=100,
        description="[m] standalone: standard deviation of the slowly drifting bias (per horizontal axis)")
    bias_tau_s: float = Field(300.0, gt=0, le=100_000,
        description="[s] standalone: the bias's correlation time (first-order Gauss-Markov)")
    vertical_factor: float = Field(1.5, ge=0, le=10,
        description="[-] the vertical bias and noise over the horizontal ones")
    position_sigma_m: float = Field(0.3, ge=0, le=100,
        description="[m] standalone: white noise of the published position (per horizontal axis)")
    velocity_sigma_m_s: float = Field(0.2, ge=0, le=20,
        description="[m/s] white noise of the published velocity (per axis)")
    rtk_sigma_m: float = Field(0.02, ge=0, le=10,
        description="[m] rtk, fixed: white noise of the published position (per horizontal axis)")
    rtk_float_sigma_m: float = Field(0.3, ge=0, le=100,
        description="[m] rtk, float: standard deviation of the float solution's wander (per horizontal axis)")
    rtk_float_tau_s: float = Field(10.0, gt=0, le=10_000,
        description="[s] rtk, float: correlation time of the float solution's wander")
    rtk_fixed_mean_s: float = Field(120.0, gt=0, le=100_000,
        description="[s] rtk: mean time between float fallbacks (exponential)")
    rtk_float_mean_s: float = Field(5.0, gt=0, le=10_000,
        description="[s] rtk: mean length of a float fallback (exponential)")
    heading_sigma_deg: float = Field(2.0, ge=0, le=45,
        description="[deg] white noise of the heading the carrier publishes (its own attitude estimate's, each state)")
    rate_hz: float = Field(10.0, gt=0, le=100, description="[Hz] how often the carrier's GNSS gives a fix")
    latency_s: float = Field(0.2, ge=0, le=5,
        description="[s] mean delay from a fix's measurement to its publication")
    jitter_s: float = Field(0.05, ge=0, le=5,
        description="[s] half-width of the uniform spread of that delay round its mean")
    seed: int = Field(0, ge=0, le=2**31 - 1, description="[-] seed of the carrier's GNSS errors")

    @model_validator(mode="after")
    def _delay(self) -> CarrierGnssSection:
        if self.jitter_s > self.latency_s:
            raise ConfigError("world.carrier_gnss.jitter_s", self.jitter_s,
                              f"must be <= world.carrier_gnss.latency_s = {self.latency_s:g} (a fix is never published before it is measured)")
        return self


class PassengerGnssSection(Section):
    """The slow GNSS bias of the passenger's own estimate, which the mock vehicle adds (off by default)."""

    bias_sigma_m: float = Field(0.0, ge=0, le=100,
        description="[m] standard deviation of the passenger estimate's slow GNSS bias (per horizontal axis; 0: none)")
    bias_tau_s: float = Field(300.0, gt=0, le=100_000,
        description="[s] the bias's correlation time (first-order Gauss-Markov)")
    vertical_factor: float = Field(1.5, ge=0, le=10, description="[-] the vertical bias over the horizontal one")
    seed: int = Field(1, ge=0, le=2**31 - 1,
        description="[-] seed of the passenger's GNSS bias (independent of the carrier's)")


class MarkerOutagesSection(Section):
    """Spells with no marker reading at all (the camera blinded, the deck's marker covered), drawn
    by the simulated world's marker sensor (off by default)."""

    fraction: float = Field(0.0, ge=0, lt=1,
        description="[-] the share of the time with no marker reading, in spells (0: none)")
    min_s: float = Field(0.3, gt=0, le=60, description="[s] the shortest spell (uniform between min_s and max_s)")
    max_s: float = Field(1.0, gt=0, le=60, description="[s] the longest spell")

    @model_validator(mode="after")
    def _spells(self) -> MarkerOutagesSection:
        if self.max_s < self.min_s:
            raise ConfigError("world.marker_outages.max_s", self.max_s,
                              f"must be >= world.marker_outages.min_s = {self.min_s:g}")
        return self


class RangefinderSection(Section):
    """The passenger's downward rangefinder as the simulated world measures it (the feed
    `rangefinder` in `mission.feeds` turns it on: the in-process simulation's sensor, and the mock
    vehicle's DISTANCE_SENSOR, `sim/vehicle/physics/rangefinder.py`): the vertical distance from the vehicle to the
    deck's top when it is over the deck (within `recovery.deck_radius_m` of its centre), else to
    the ground (`scenario.carrier_start`'s height)."""

    sigma_m: float = Field(0.03, gt=0, le=5, description="[m] white noise of each range (standard deviation)")
    rate_hz: float = Field(25.0, gt=0, le=200, description="[Hz] how often the rangefinder measures")
    latency_s: float = Field(0.03, ge=0, le=2, description="[s] from a range's capture to its delivery")
    max_range_m: float = Field(10.0, gt=0, le=100, description="[m] beyond this (or below 0) it gives no reading")
    dropout_fraction: float = Field(0.02, ge=0, lt=1, description="[-] the share of ranges lost, each on its own")


class WorldSection(Section):
    """The simulated world's errors (read by the simulators only)."""

    carrier_gnss: CarrierGnssSection = Field(CarrierGnssSection(),
        description="[-] the error of the carrier's published GNSS state (`[world.carrier_gnss]`)")
    passenger_gnss: PassengerGnssSection = Field(PassengerGnssSection(),
        description="[-] the slow GNSS bias of the passenger's own estimate (`[world.passenger_gnss]`)")
    marker_outages: MarkerOutagesSection = Field(MarkerOutagesSection(),
        description="[-] spells with no marker reading (`[world.marker_outages]`)")
    rangefinder: RangefinderSection = Field(RangefinderSection(),
        description="[-] the passenger's downward rangefinder (`[world.rangefinder]`; the feed `rangefinder`)")
