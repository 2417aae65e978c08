"""What the measurement feeds give the phases (pure records): one :class:`Measurement` per
sensor reading, stamped at capture, and :class:`Measurements`, the typed slot of
:class:`~mission.phases.types.Observation` that holds them.

A feed is a :class:`mission.interfaces.MeasurementSource` (``poll(t_s)`` -> measurements): in
flight an I/O-side module the configuration names (``mission.feeds``), in the in-process
simulation a sensor of the simulated world of the same name. Both return the records below; the
passenger's step (:class:`mission.passenger.step.PassengerStep`) puts them in the observation and
keeps the newest of each kind; a phase, or an estimator, reads them by their class
(:meth:`Measurements.latest`, :meth:`Measurements.arrived`). docs/how-it-works.md, "Adding a
measurement feed", lists what a new feed touches.

Frames: local NED [m]; times [s] on the mission clock (a feed moves a sensor's own capture time
onto it, as the carrier feed does with the carrier's stamps).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

import numpy as np


@dataclass(frozen=True)
class Measurement:
    """One reading of a sensor: ``capture_t_s`` [s] when the sensor captured it, on the mission
    clock. A kind of measurement is a frozen subclass adding what it measured."""

    capture_t_s: float

    def age_s(self, t_s: float) -> float:
        """Its age [s] at ``t_s`` [s] (from capture, not from arrival)."""
        return t_s - self.capture_t_s


@dataclass(frozen=True)
class RelativePosition(Measurement):
    """Where a point of the carrier (a marker on its deck, say) was relative to the vehicle at
    capture: ``offset_ned_m`` [m] NED, the point's position less the vehicle's (a camera's
    detection rotated by the vehicle's attitude at capture: the feed's work); ``sigma_m`` [m] its
    standard deviation per axis (None: not stated); ``marker``: which point (a marker's id)."""

    offset_ned_m: np.ndarray
    sigma_m: float | None = None
    marker: int = 0


@dataclass(frozen=True)
class DownwardRange(Measurement):
    """A downward rangefinder's reading at capture: ``range_m`` [m] from the vehicle's reference
    point straight down (the NED down axis: a level vehicle's body-down axis) to whatever is
    below it, the carrier's deck when it is over it, else the ground; ``sigma_m`` [m] its
    standard deviation (None: not stated)."""

    range_m: float
    sigma_m: float | None = None


M = TypeVar("M", bound=Measurement)


@dataclass(frozen=True)
class Measurements:
    """The measurements one tick sees: ``new`` those polled on this tick (each measurement
    appears on exactly one tick, in capture order: what a filter updates on), ``held`` the newest
    of each kind so far, one per class (what a phase that needs only the last fix reads)."""

    new: tuple[Measurement, ...] = ()
    held: tuple[Measurement, ...] = ()

    def arrived(self, kind: type[M]) -> tuple[M, ...]:
        """The measurements of ``kind`` (or a subclass) polled on this tick, oldest capture first."""
        return tuple(m for m in self.new if isinstance(m, kind))

    def latest(self, kind: type[M]) -> M | None:
        """The newest measurement of ``kind`` (or a subclass) so far, this tick's or older (None: none yet)."""
        found = [m for m in self.held if isinstance(m, kind)]
        return max(found, key=lambda m: m.capture_t_s) if found else None

    def then(self, arrived: tuple[Measurement, ...]) -> Measurements:
        """The next tick's: ``arrived`` (sorted by capture time) and the newest of each kind held."""
        now = tuple(sorted(arrived, key=lambda m: m.capture_t_s))
        newest = {type(m): m for m in self.held}
        for m in now:
            old = newest.get(type(m))
            if old is None or m.capture_t_s >= old.capture_t_s:  # a late reading never replaces a newer one
                newest[type(m)] = m
        return Measurements(now, tuple(newest.values()))
