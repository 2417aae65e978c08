"""The passenger's downward rangefinder as a sensor of the in-process mission simulation
(:class:`sim.batch.recovery.World`, feed name ``rangefinder``): the vertical distance from the
vehicle's true position to what is below it, each reading a
:class:`~mission.phases.measurements.DownwardRange` stamped at capture and delivered
``world.rangefinder.latency_s`` later.

Below the vehicle is the deck's top when the vehicle is within ``recovery.deck_radius_m`` of the
deck's centre horizontally (the seat: :func:`mission.passenger.relative.seat_offset` from the
carrier's true reference point, at its height), else the ground (``scenario.carrier_start``'s
height). Vertical, not along the body's down axis: the mock's physics keeps the vehicle level.
Each range has white noise ``sigma_m``; one beyond ``max_range_m`` or below 0 gives no reading,
and ``dropout_fraction`` of them are lost, each on its own. Captures happen on the world's ticks
at ``rate_hz`` at most; every draw is seeded by the scenario's seed.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mission.passenger.relative import seat_offset
from mission.phases.measurements import DownwardRange, Measurement
from sim.batch.sensors import CaptureGrid

if TYPE_CHECKING:
    from sim.batch.recovery import World

SEED_OFFSET = 9133  # the rangefinder's stream, apart from the other seeded streams of the scenario's seed


class WorldRangefinder:
    """The world's downward rangefinder; a :class:`mission.interfaces.MeasurementSource`."""

    def __init__(self, world: World) -> None:
        cfg = world.cfg
        self.world, self.cfg = world, cfg.world.rangefinder
        self.grid: CaptureGrid[DownwardRange] = CaptureGrid(1.0 / self.cfg.rate_hz, self.cfg.latency_s)
        self.seat = seat_offset(np.asarray(cfg.mission.dock_offset_ned_m, float), cfg.mission.ride == "deck")
        self.radius_m = cfg.recovery.deck_radius_m
        self.ground_d_m = float(cfg.scenario.carrier_start[2]) if len(cfg.scenario.carrier_start) > 2 else 0.0
        self.rng = np.random.default_rng(world.scenario.seed + SEED_OFFSET)
        self.captured = 0  # ranges measured (a reading or not)

    def true_range_m(self, t_s: float) -> float:
        """The true vertical distance [m] from the vehicle down to the deck's top (over the deck) or the ground."""
        vehicle = self.world.vehicle.true_position
        deck = self.world.carrier.true_at(t_s)[0] + self.seat
        over = float(np.hypot(*(deck[:2] - vehicle[:2]))) <= self.radius_m
        return float((deck[2] if over else self.ground_d_m) - vehicle[2])

    def poll(self, t_s: float) -> list[Measurement]:
        """Measure if a range is due at ``t_s`` [s]; deliver what is ``latency_s`` old."""
        c = self.cfg
        if self.grid.due(t_s):
            self.captured += 1
            noisy = self.true_range_m(t_s) + float(self.rng.normal(0.0, c.sigma_m))
            lost = self.rng.random() < c.dropout_fraction
            if not lost and 0.0 <= noisy <= c.max_range_m:
                self.grid.hold(DownwardRange(capture_t_s=t_s, range_m=noisy, sigma_m=c.sigma_m))
        return list(self.grid.deliver(t_s))

    def close(self) -> None:
        self.grid.clear()


def rangefinder(world: World) -> WorldRangefinder:
    """The downward rangefinder (feed ``rangefinder``)."""
    return WorldRangefinder(world)
