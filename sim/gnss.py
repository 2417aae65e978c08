"""The world's GNSS errors: what the carrier publishes of itself, and the passenger's own bias.

Real GNSS puts each vehicle on a frame of its own: a standalone receiver's position wanders by
metres over minutes, and two receivers' wanders are independent, so the carrier's published
position and the passenger's own estimate do not share an origin. The simulators add these
errors to what the vehicles report (the controller never does: it sees them only in what it is
sent). All seeded; the statistics are ``[world]`` of the configuration
(:mod:`mission.config.relnav`), off unless asked; the models and their measured statistics are in
docs/relnav.md.

- :class:`GaussMarkovBias`: a slowly drifting bias (first-order Gauss-Markov per axis, time
  constant minutes, the vertical axis scaled), the error of a standalone fix (the passenger's own
  slow bias is in the mock vehicle's estimate: :class:`sim.vehicle.estimator.BiasedEstimateError`);
- :class:`CarrierGnss`: the carrier's published GNSS state: fixes at ``rate_hz``, each the truth
  plus the bias and white noise (standalone), or plus centimetres with occasional float
  fallbacks at decimetres (moving-base RTK), stamped with its measurement time and published
  ``latency_s`` +- ``jitter_s`` later; and its heading with white noise;
- :class:`ErringCarrier`: a carrier backend whose own state is what :class:`CarrierGnss`
  publishes of the wrapped backend's true state (the carrier steers on it and publishes it),
  with the wrapped backend's velocity as the robot's inertial one (what its acceleration is
  measured from: an autopilot's velocity comes from its IMU, not only from the fixes).

Units SI, NED, simulated seconds.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from mission.carrier.backends import CarrierBackend, OwnState
from mission.config.relnav import CarrierGnssSection


class GaussMarkovBias:
    """A 3-axis first-order Gauss-Markov bias [m]: standard deviation ``sigma_m`` per horizontal
    axis (times ``vertical_factor`` on down), correlation time ``tau_s`` [s] (autocorrelation
    ``exp(-|t|/tau)``); starts stationary. :meth:`advance` moves it on exactly (any step)."""

    def __init__(self, sigma_m: float, tau_s: float, vertical_factor: float, rng: np.random.Generator) -> None:
        self.sigma_ned_m = np.array([sigma_m, sigma_m, sigma_m * vertical_factor], dtype=float)
        self.tau_s = tau_s
        self._rng = rng
        self.value_ned_m = self.sigma_ned_m * rng.standard_normal(3)

    def advance(self, dt_s: float) -> np.ndarray:
        """The bias ``dt_s`` [s] later."""
        if dt_s > 0.0:
            decay = math.exp(-dt_s / self.tau_s)
            kick = self.sigma_ned_m * math.sqrt(-math.expm1(-2.0 * dt_s / self.tau_s))
            self.value_ned_m = self.value_ned_m * decay + kick * self._rng.standard_normal(3)
        return self.value_ned_m


@dataclass(frozen=True)
class GnssFix:
    """One published fix: measured at ``t_s`` [s], published at ``published_t_s`` [s];
    ``position_ned_m`` (3,) [m], ``velocity_ned_m_s`` (3,) [m/s] with their errors;
    ``error_ned_m`` (3,): the position's error [m] (the truth is ``position_ned_m - error_ned_m``);
    ``float_solution``: an RTK fix that fell back to float."""

    t_s: float
    published_t_s: float
    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    error_ned_m: np.ndarray
    float_solution: bool = False


class CarrierGnss:
    """The carrier's published GNSS state with the errors of ``cfg`` (module docstring).
    :meth:`observe` the true state as the simulation steps; it returns the fixes published by then."""

    def __init__(self, cfg: CarrierGnssSection) -> None:
        self.cfg = cfg
        rng = self._rng = np.random.default_rng(cfg.seed)
        scale = np.array([1.0, 1.0, cfg.vertical_factor])
        self._noise_ned_m = scale * (cfg.position_sigma_m if cfg.mode == "standalone" else cfg.rtk_sigma_m)
        self._velocity_noise_m_s = cfg.velocity_sigma_m_s
        self.bias = GaussMarkovBias(cfg.bias_sigma_m if cfg.mode == "standalone" else 0.0, cfg.bias_tau_s,
                                    cfg.vertical_factor, rng)
        self._wander = GaussMarkovBias(cfg.rtk_float_sigma_m, cfg.rtk_float_tau_s, cfg.vertical_factor, rng)
        self.float_solution = False
        self._switch_t_s = math.nan  # RTK: when the solution next changes between fixed and float
        self._next_t_s = math.nan  # when the next fix is measured
        self._pending: list[GnssFix] = []  # measured, not yet published
        # the heading's noise draws on a stream of its own: the fixes' errors stay as they were
        self._heading_rng = np.random.default_rng([cfg.seed, 1])

    def heading(self, yaw_rad: float | None) -> float | None:
        """The heading [rad] the carrier publishes for its true ``yaw_rad`` (None: it has none):
        its own attitude estimate, with ``heading_sigma_deg`` of white noise (no GNSS frame: a
        heading has no origin to be off by)."""
        if yaw_rad is None or self.cfg.heading_sigma_deg <= 0.0:
            return yaw_rad
        return math.remainder(yaw_rad + math.radians(self.cfg.heading_sigma_deg) * self._heading_rng.standard_normal(),
                              2.0 * math.pi)

    def observe(self, t_s: float, position_ned_m: np.ndarray, velocity_ned_m_s: np.ndarray) -> list[GnssFix]:
        """The true state at ``t_s`` [s] (position [m], velocity [m/s]); returns the fixes
        published in ``(previous call, t_s]``, in the order they were published."""
        cfg = self.cfg
        if math.isnan(self._next_t_s):
            self._next_t_s = t_s
            self._switch_t_s = t_s + self._rng.exponential(cfg.rtk_fixed_mean_s)
        period = 1.0 / cfg.rate_hz
        while self._next_t_s <= t_s:  # a fix of the truth at its own time (moved back along the velocity)
            t_fix = self._next_t_s
            truth = np.asarray(position_ned_m, dtype=float) - np.asarray(velocity_ned_m_s, dtype=float) * (t_s - t_fix)
            self._pending.append(self._fix(t_fix, truth, np.asarray(velocity_ned_m_s, dtype=float), period))
            self._next_t_s = t_fix + period
        out = sorted((f for f in self._pending if f.published_t_s <= t_s), key=lambda f: f.published_t_s)
        self._pending = [f for f in self._pending if f.published_t_s > t_s]
        return out

    def _fix(self, t_s: float, truth_m: np.ndarray, velocity_m_s: np.ndarray, period_s: float) -> GnssFix:
        cfg, rng = self.cfg, self._rng
        error = self.bias.advance(period_s) + self._noise_ned_m * rng.standard_normal(3)
        wander = self._wander.advance(period_s)
        if cfg.mode == "rtk":
            while t_s >= self._switch_t_s:
                self.float_solution = not self.float_solution
                mean = cfg.rtk_float_mean_s if self.float_solution else cfg.rtk_fixed_mean_s
                self._switch_t_s += rng.exponential(mean)
            if self.float_solution:
                error = error + wander
        delay = cfg.latency_s + (rng.uniform(-cfg.jitter_s, cfg.jitter_s) if cfg.jitter_s > 0 else 0.0)
        velocity = velocity_m_s + self._velocity_noise_m_s * rng.standard_normal(3)
        return GnssFix(t_s, t_s + delay, truth_m + error, velocity, error, self.float_solution)


class ErringCarrier:
    """A carrier backend (:class:`mission.carrier.backends.CarrierBackend`) whose own state is the
    newest fix :class:`CarrierGnss` has published of ``inner``'s true state: the
    carrier steers on it and publishes it, as a real one does with its GNSS. Its ``inertial`` state
    (:class:`~mission.carrier.backends.OwnState`) is ``inner``'s.
    Everything else is ``inner``'s; :attr:`truth` is ``inner``'s own state."""

    def __init__(self, inner: CarrierBackend, cfg: CarrierGnssSection) -> None:
        self.inner, self.gnss = inner, CarrierGnss(cfg)
        self.name, self.brakes_itself = inner.name, inner.brakes_itself
        self._latest: GnssFix | None = None
        self._yaw_rad: float | None = None

    @property
    def truth(self) -> OwnState | None:
        return self.inner.own_state()

    def own_state(self) -> OwnState | None:
        truth = self.inner.own_state()
        if truth is not None:
            self._yaw_rad = self.gnss.heading(truth.yaw_rad)
            for fix in self.gnss.observe(truth.t_s, truth.position_ned_m, truth.velocity_ned_m_s):
                if self._latest is None or fix.t_s > self._latest.t_s:
                    self._latest = fix
        f = self._latest
        if f is None:
            return None
        return OwnState(f.t_s, f.position_ned_m.copy(), f.velocity_ned_m_s.copy(), self._yaw_rad, inertial=truth)

    def advance(self, dt_s: float) -> None:
        self.inner.advance(dt_s)

    def engage(self) -> None:
        self.inner.engage()

    def control_fault(self) -> str | None:
        return self.inner.control_fault()

    def command(self, cmd: Any) -> None:
        self.inner.command(cmd)

    def park(self) -> None:
        self.inner.park()

    def lockstep_relay(self, session: Any) -> Any:
        return self.inner.lockstep_relay(session)

    def close(self) -> None:
        self.inner.close()
