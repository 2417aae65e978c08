"""The errors of PX4's state estimate, as the mock vehicle adds them (by default PX4 SITL's).

What PX4 SITL shows (SIH quadrotor, EKF2 on SIH's simulated GPS; its estimate against SIH's
true state, streamed as HIL_STATE_QUATERNION: holding a point, ``python -m bench.px4_hold``,
docs/px4-hold.md; and over three whole offboard sequences, ``python -m bench.px4_response_record``,
``tests/data/px4_responses/unseen*.csv.gz``; docs/mock-vehicle.md):

- the estimate's *velocity* is off by 0.22-0.25 m/s RMS per horizontal axis (quadratic mean;
  0.12-0.15 north, 0.26-0.33 east), 0.16-0.20 vertically, an error that keeps its sign for
  seconds (autocorrelation 0.95 at 0.5 s, 0.86 at 1 s, 0.65 at 2 s, 0.24 at 4 s, -0.2-0 at 8 s) and
  that the estimate's *position* does not share: the reported velocity says 0.3 m/s while the
  reported position stands still (their correlation is only ~0.3). It is as large under a
  velocity setpoint as holding a position (20 s of each: 0.11-0.25 / 0.27-0.50 m/s and
  0.07-0.14 / 0.19-0.37 m/s north / east);
- the estimate's position is off by 0.10-0.15 m RMS per horizontal axis (0.2-0.5 m vertically),
  slower (autocorrelation 0.9 at 1 s, 0.7 at 2 s, 0.3 at 4 s), around a bias of a few decimetres.

PX4 flies its estimate: its position controller is fed the estimated position and velocity, and
its telemetry reports them. So under a position setpoint a velocity error ``e_v`` moves the held
position estimate by ``e_v / k`` (``k`` the position loop's gain: 0.95/s for PX4 alone), and the
true vehicle moves whenever the errors change.

Model: per axis two independent second-order Gauss-Markov processes (white noise through two
first-order lags: smooth, as an estimator's errors are), the velocity error (standard deviation
``sigma_v`` [m/s], lag time constant ``tau_v`` [s]) and the position error (``sigma_p`` [m],
``tau_p`` [s]); the vertical sigmas are the horizontal ones times the
``vertical_*`` factors. Seeded: the same seed gives the same errors. The errors' clock starts
when the vehicle first takes off (before that they hold their first draw): a flight whose
start-up takes longer (a link's round trips to arm and switch mode) meets the same errors from
the same moment of its flight. :data:`PX4_SITL` holds
the values fitted to PX4 SITL; ``scale`` multiplies both sigmas (:data:`PX4_SITL_SCALE`, the mock's
default: PX4 SITL's; 0: an exact estimate). Units SI, NED; time in simulated seconds.
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass

from mission.config.relnav import PassengerGnssSection

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class ErrorModel:
    """The statistics of the estimate's errors (see the module docstring)."""

    sigma_v_m_s: float
    tau_v_s: float
    sigma_p_m: float
    tau_p_s: float
    vertical_v: float = 0.7  # vertical velocity error sigma over the horizontal one [-]
    vertical_p: float = 2.0  # vertical position error sigma over the horizontal one [-]

    def scaled(self, scale: float) -> ErrorModel:
        return ErrorModel(self.sigma_v_m_s * scale, self.tau_v_s, self.sigma_p_m * scale, self.tau_p_s, self.vertical_v,
                          self.vertical_p)


# PX4 SITL's (SIH quadrotor): the velocity error's sigma and correlation time as its truth measured them over
# three offboard sequences (bench/px4_response_record.py; 1.5 s gives its autocorrelation within 0.04 at 0.5-4 s),
# the position error's fitted holding a point (bench/px4_hold.py, docs/px4-hold.md)
PX4_SITL = ErrorModel(sigma_v_m_s=0.25, tau_v_s=1.5, sigma_p_m=0.15, tau_p_s=1.7)
PX4_SITL_SCALE = 1.0  # the mock vehicle's default scale of PX4_SITL: PX4 SITL's own errors [-]


class EstimateError:
    """Seeded errors of the estimate; :meth:`advance` once per physics step, then
    :attr:`position` [m] and :attr:`velocity` [m/s] NED are what the estimate adds to the truth.
    :attr:`started`: the errors' clock runs (from the first step flown)."""

    def __init__(self, scale: float, model: ErrorModel = PX4_SITL, seed: int | None = 0) -> None:
        if not scale >= 0:
            raise ValueError(f"estimate error scale must be >= 0, got {scale!r}")
        self.model = m = model.scaled(float(scale))
        self._rng = random.Random(None if seed is None else seed + 104729)
        sigma_v = (m.sigma_v_m_s, m.sigma_v_m_s, m.sigma_v_m_s * m.vertical_v)
        sigma_p = (m.sigma_p_m, m.sigma_p_m, m.sigma_p_m * m.vertical_p)
        self._v = [_GaussMarkov2(s, m.tau_v_s, self._rng) for s in sigma_v]
        self._p = [_GaussMarkov2(s, m.tau_p_s, self._rng) for s in sigma_p]
        self.velocity: Vec3 = (self._v[0].value, self._v[1].value, self._v[2].value)
        self.position: Vec3 = (self._p[0].value, self._p[1].value, self._p[2].value)
        self.started = False

    @property
    def enabled(self) -> bool:
        return self.model.sigma_v_m_s > 0.0 or self.model.sigma_p_m > 0.0

    def advance(self, dt_s: float, flown: bool = True) -> None:
        """One step of ``dt_s`` [s] (much shorter than the correlation times) of every error;
        ``flown``: the vehicle has taken off (PX4's land detector). Until the first step flown the
        errors keep their first draw."""
        if not self.enabled or not (self.started or flown):
            return
        self.started = True
        v, p = self._v, self._p
        self.velocity = (v[0].advance(dt_s), v[1].advance(dt_s), v[2].advance(dt_s))
        self.position = (p[0].advance(dt_s), p[1].advance(dt_s), p[2].advance(dt_s))


class _GaussMarkov2:
    """A second-order Gauss-Markov process: white noise through two first-order lags of time
    constant ``tau_s``; standard deviation ``sigma``, autocorrelation ``(1 + t/tau) exp(-t/tau)``
    (smooth: its rate is finite, unlike a first-order process's). Starts stationary."""

    def __init__(self, sigma: float, tau_s: float, rng: random.Random) -> None:
        self.tau_s, self._rng = tau_s, rng
        self._dt_s, self._decay, self._kick = math.nan, 0.0, 0.0  # the last step's constants
        self._inner_sigma = sigma * math.sqrt(2.0)  # the second lag halves the variance
        # a stationary start: (inner, value) jointly Gaussian with correlation 1/sqrt(2)
        g1, g2 = rng.gauss(0.0, 1.0), rng.gauss(0.0, 1.0)
        self._inner = self._inner_sigma * g1
        self.value = sigma * (g1 / math.sqrt(2.0) + g2 / math.sqrt(2.0))

    def advance(self, dt_s: float) -> float:
        if dt_s != self._dt_s:  # the mock's steps are fixed: computed once
            decay = math.exp(-dt_s / self.tau_s)
            self._dt_s, self._decay, self._kick = dt_s, decay, self._inner_sigma * math.sqrt(1.0 - decay * decay)
        decay = self._decay
        self._inner = self._inner * decay + self._kick * self._rng.gauss(0.0, 1.0)
        self.value += (self._inner - self.value) * (1.0 - decay)
        return self.value


class BiasedEstimateError(EstimateError):
    """:class:`EstimateError` plus the passenger's own slow GNSS bias on the position
    (``[world.passenger_gnss]``, seeded by its own seed, independent of the carrier's): per axis a
    second-order Gauss-Markov process (smooth, as an estimator's output is) of standard deviation
    ``bias_sigma_m`` (times ``vertical_factor`` on down) and time constant ``bias_tau_s``: the
    estimate's origin drifts by metres over minutes as a standalone receiver's does, and PX4
    flies it. Always enabled; ``scale`` as :class:`EstimateError`'s."""

    def __init__(self, scale: float, gnss: PassengerGnssSection, model: ErrorModel = PX4_SITL, seed: int | None = 0) -> None:
        super().__init__(scale, model, seed)
        rng = random.Random(gnss.seed + 7919)
        sigma = (gnss.bias_sigma_m, gnss.bias_sigma_m, gnss.bias_sigma_m * gnss.vertical_factor)
        self._bias = [_GaussMarkov2(s, gnss.bias_tau_s, rng) for s in sigma]
        self._with_bias()

    @property
    def enabled(self) -> bool:
        return True

    @property
    def gnss_bias(self) -> Vec3:
        """The GNSS bias part of :attr:`position` [m] NED."""
        b = self._bias
        return (b[0].value, b[1].value, b[2].value)

    def advance(self, dt_s: float, *args: bool) -> None:
        super().advance(dt_s, *args)
        if getattr(self, "started", True):  # the errors' clock runs (one that holds until take-off holds this too)
            for b in self._bias:
                b.advance(dt_s)
        self._with_bias()

    def _with_bias(self) -> None:
        (b, p) = (self.gnss_bias, self._p)
        self.position = (p[0].value + b[0], p[1].value + b[1], p[2].value + b[2])
