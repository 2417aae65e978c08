"""The passenger's downward rangefinder: one model for the in-process simulation's sensor
(:mod:`sim.batch.rangefinder`) and the mock vehicle's DISTANCE_SENSOR (:class:`sim.vehicle.mock.MockVehicle`).

Geometry (:func:`range_below_m`): the vertical distance [m] from the vehicle's true position down
to the deck's top when the vehicle is within ``radius_m`` of the deck's centre horizontally, else
down to the ground (``ground_d_m``, NED down [m]). Vertical, not along the body's down axis: the
mock's physics keeps the vehicle level.

Errors and timing (:class:`Rangefinder`, ``[world.rangefinder]``): captures on the caller's ticks at
``rate_hz`` at most (:class:`~sim.batch.sensors.CaptureGrid`, from t = 0), each range with white
noise ``sigma_m``; one beyond ``max_range_m`` or below 0 gives no reading, and
``dropout_fraction`` of them are lost, each on its own; a reading is delivered ``latency_s``
after its capture. Draws from ``seed + SEED_OFFSET``: per capture one normal, then one uniform.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from mission.config.relnav import RangefinderSection
from mission.phases.measurements import DownwardRange
from sim.batch.sensors import CaptureGrid

SEED_OFFSET = 9133  # the rangefinder's stream, apart from the other seeded streams of the same seed


def range_below_m(vehicle_ned_m: Sequence[float], deck_top_ned_m: Sequence[float] | None, radius_m: float,
                  ground_d_m: float) -> float:
    """The true vertical distance [m] from ``vehicle_ned_m`` down to the deck's top
    ``deck_top_ned_m`` (its centre, NED [m]; None: no deck) when within ``radius_m`` [m] of it
    horizontally, else down to the ground at ``ground_d_m`` [m, NED down]."""
    vehicle_d = float(vehicle_ned_m[2])
    if deck_top_ned_m is not None:
        off_n = float(deck_top_ned_m[0]) - float(vehicle_ned_m[0])
        off_e = float(deck_top_ned_m[1]) - float(vehicle_ned_m[1])
        if math.hypot(off_n, off_e) <= radius_m:
            return float(deck_top_ned_m[2]) - vehicle_d
    return ground_d_m - vehicle_d


class Rangefinder:
    """The rangefinder's errors and timing (module docstring), whatever world it measures."""

    def __init__(self, cfg: RangefinderSection, seed: int) -> None:
        self.cfg = cfg
        self.grid: CaptureGrid[DownwardRange] = CaptureGrid(1.0 / cfg.rate_hz, cfg.latency_s)
        self.rng = np.random.default_rng(seed + SEED_OFFSET)
        self.captured = 0  # ranges measured (a reading or not)

    def capture(self, t_s: float, true_range_m: Callable[[], float]) -> None:
        """Measure ``true_range_m()`` [m] if a capture is due at the tick ``t_s`` [s]; a reading
        (not lost, within the limits) is held for delivery."""
        c = self.cfg
        if not self.grid.due(t_s):
            return
        self.captured += 1
        noisy = true_range_m() + float(self.rng.normal(0.0, c.sigma_m))
        lost = self.rng.random() < c.dropout_fraction
        if not lost and 0.0 <= noisy <= c.max_range_m:
            self.grid.hold(DownwardRange(capture_t_s=t_s, range_m=noisy, sigma_m=c.sigma_m))

    def deliver(self, t_s: float) -> list[DownwardRange]:
        """The readings ``latency_s`` old or older at ``t_s`` [s], in capture order, each once."""
        return self.grid.deliver(t_s)

    def next_delivery_s(self) -> float | None:
        """When [s] the oldest held reading is due (None: none held)."""
        pending = self.grid.pending
        return None if not pending else pending[0].capture_t_s + self.grid.latency_s

    def clear(self) -> None:
        self.grid.clear()
