"""The wander of PX4's position estimate, as the mock vehicle can add it (off by default).

On PX4 SITL the reported position drifts away from the integral of the reported velocity by
metres over a minute (../shared/px4_sitl/responses: 3-6 m range per axis over 130 s, a drift rate
of 0.13-0.25 m/s with a correlation time of about 3-4 s; EKF2 fusing SIH's noisy GPS). PX4 flies
its estimate, so under a position setpoint the true vehicle moves against the wander, and under
velocity setpoints the reported track wanders while the vehicle does not.

Model: the estimate's error ``offset`` [m] NED integrates a rate [m/s] that is an
Ornstein-Uhlenbeck process of standard deviation ``sigma_m_s`` and correlation time ``tau_s``,
seeded (same seed, same wander). Units SI; time in simulated seconds.
"""
from __future__ import annotations

import math
import random
from dataclasses import replace

from sim.vehicle.physics.multicopter import Command

PX4_SITL_DRIFT_SIGMA_M_S = 0.18  # std of the drift rate measured on the recordings (N 0.15, E 0.24, D 0.15)
PX4_SITL_DRIFT_TAU_S = 3.5  # its correlation time (autocorrelation 0.6 at 2 s, 0.3 at 4 s)


class EstimateDrift:
    """Seeded wander of the position estimate; :meth:`advance` once per physics step."""

    def __init__(self, sigma_m_s: float, tau_s: float = PX4_SITL_DRIFT_TAU_S, seed: int | None = 0) -> None:
        if sigma_m_s < 0 or not tau_s > 0:
            raise ValueError(f"estimate drift: sigma must be >= 0 and tau > 0, got {sigma_m_s!r}, {tau_s!r}")
        self.sigma_m_s, self.tau_s = float(sigma_m_s), float(tau_s)
        self._rng = random.Random(None if seed is None else seed + 104729)
        self.rate = [0.0, 0.0, 0.0]
        self.offset = (0.0, 0.0, 0.0)

    @property
    def enabled(self) -> bool:
        return self.sigma_m_s > 0.0

    def advance(self, dt_s: float) -> None:
        """One exact OU step of the rate, then the offset integrates it."""
        if not self.enabled:
            return
        decay = math.exp(-dt_s / self.tau_s)
        spread = self.sigma_m_s * math.sqrt(1.0 - decay * decay)
        gauss = self._rng.gauss
        self.rate = [r * decay + spread * gauss(0.0, 1.0) for r in self.rate]
        o = self.offset
        self.offset = (o[0] + self.rate[0] * dt_s, o[1] + self.rate[1] * dt_s, o[2] + self.rate[2] * dt_s)


def flown_on_estimate(command: Command, offset: tuple[float, float, float]) -> Command:
    """The command as the true vehicle feels it when PX4 flies its estimate (true + ``offset``)
    to a position setpoint: the setpoint moves by ``-offset`` (velocities are unaffected)."""
    p = command.position_ned_m
    if all(math.isnan(x) for x in p):
        return command
    return replace(command, position_ned_m=(p[0] - offset[0], p[1] - offset[1], p[2] - offset[2]))
