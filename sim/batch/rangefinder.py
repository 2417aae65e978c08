"""The passenger's downward rangefinder as a sensor of the in-process mission simulation
(:class:`sim.batch.recovery.World`, feed name ``rangefinder``): the vertical distance from the
vehicle's true position to what is below it, each reading a
:class:`~mission.phases.measurements.DownwardRange` stamped at capture and delivered
``world.rangefinder.latency_s`` later.

Below the vehicle is the deck's top when the vehicle is within ``recovery.deck_radius_m`` of the
deck's centre horizontally (the seat: :func:`mission.passenger.relative.seat_offset` from the
carrier's true reference point, at its height), else the ground (``scenario.carrier_start``'s
height). The model (geometry, noise, limits, dropouts, the capture grid, the draws seeded by the
scenario's seed) is :mod:`sim.vehicle.physics.rangefinder`'s, which the mock vehicle's
DISTANCE_SENSOR measures with too.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mission.passenger.relative import seat_offset
from mission.phases.measurements import Measurement
from sim.vehicle.physics.rangefinder import Rangefinder, range_below_m

if TYPE_CHECKING:
    from sim.batch.recovery import World


class WorldRangefinder:
    """The world's downward rangefinder; a :class:`mission.interfaces.MeasurementSource`."""

    def __init__(self, world: World) -> None:
        cfg = world.cfg
        self.world, self.cfg = world, cfg.world.rangefinder
        self.sensor = Rangefinder(self.cfg, world.scenario.seed)
        self.seat = seat_offset(np.asarray(cfg.mission.dock_offset_ned_m, float), cfg.mission.ride == "deck")
        self.radius_m = cfg.recovery.deck_radius_m
        self.ground_d_m = float(cfg.scenario.carrier_start[2]) if len(cfg.scenario.carrier_start) > 2 else 0.0

    @property
    def captured(self) -> int:
        """Ranges measured (a reading or not)."""
        return self.sensor.captured

    def true_range_m(self, t_s: float) -> float:
        """The true vertical distance [m] from the vehicle down to the deck's top (over the deck) or the ground."""
        deck = self.world.carrier.true_at(t_s)[0] + self.seat
        return range_below_m(self.world.vehicle.true_position, deck, self.radius_m, self.ground_d_m)

    def poll(self, t_s: float) -> list[Measurement]:
        """Measure if a range is due at ``t_s`` [s]; deliver what is ``latency_s`` old."""
        self.sensor.capture(t_s, lambda: self.true_range_m(t_s))
        return list(self.sensor.deliver(t_s))

    def close(self) -> None:
        self.sensor.clear()


def rangefinder(world: World) -> WorldRangefinder:
    """The downward rangefinder (feed ``rangefinder``)."""
    return WorldRangefinder(world)
