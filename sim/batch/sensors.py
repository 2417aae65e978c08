"""The simulated world's measurement sensors: for each measurement feed the configuration names
(``mission.feeds``), the sensor of the same name that the in-process simulation
(:class:`sim.batch.recovery.World`) polls in its place.

A sensor is registered in ``pyproject.toml``'s entry-point group ``marsupial.sensors`` as a
:data:`SensorFactory`: called once with the world, it returns a
:class:`mission.interfaces.MeasurementSource` whose ``poll(t_s)`` measures that world (its true
vehicle, its carrier) at the tick's time, with the sensor's own errors, latency and dropouts, and
stamps each reading at capture. The world polls it after the vehicle reached the tick and hands
the readings to the passenger's step, as the flight loop does with the feed it stands in for.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Generic, TypeVar

from mission.cli.subcommands import SENSORS_GROUP, entry_points, load
from mission.config.schema import Config
from mission.errors import ConfigError
from mission.interfaces import MeasurementSource
from mission.phases.measurements import Measurement

if TYPE_CHECKING:
    from sim.batch.recovery import World

#: A sensor of the simulated world: the world in, the measurement source that measures it out.
SensorFactory = Callable[["World"], MeasurementSource]

M = TypeVar("M", bound=Measurement)


class CaptureGrid(Generic[M]):
    """A sensor's timing: captures every ``period_s`` [s] at most, on the world's ticks from t = 0
    (:meth:`due`), each reading delivered ``latency_s`` [s] after its capture (:meth:`hold`, then
    :meth:`deliver`)."""

    def __init__(self, period_s: float, latency_s: float) -> None:
        self.period_s, self.latency_s = period_s, latency_s
        self.next_s = 0.0
        self.pending: list[M] = []  # captured, not yet delivered

    def due(self, t_s: float) -> bool:
        """Whether a capture is due at the tick ``t_s`` [s] (if so, the next is a period on)."""
        if t_s + 1e-9 < self.next_s:
            return False
        self.next_s = max(self.next_s + self.period_s, t_s)
        return True

    def hold(self, reading: M) -> None:
        """A reading captured (at its ``capture_t_s``), delivered once it is ``latency_s`` old."""
        self.pending.append(reading)

    def deliver(self, t_s: float) -> list[M]:
        """The readings ``latency_s`` old or older at ``t_s`` [s], in capture order."""
        out = [m for m in self.pending if m.capture_t_s + self.latency_s <= t_s + 1e-9]
        self.pending = [m for m in self.pending if m.capture_t_s + self.latency_s > t_s + 1e-9]
        return out

    def clear(self) -> None:
        self.pending = []


def sensors_for(cfg: Config) -> list[SensorFactory]:
    """The sensor of each feed ``mission.feeds`` names, from the entry-point group
    ``marsupial.sensors``; :class:`ConfigError` for a feed the simulation has no sensor for."""
    known = entry_points(SENSORS_GROUP)
    missing = [name for name in cfg.mission.feeds if name not in known]
    if missing:
        raise ConfigError("mission.feeds", missing, f"the simulation has no sensor for these feeds (entry points "
                          f"{SENSORS_GROUP}: {sorted(known) or 'none'})")
    found: list[Any] = [load(known[name]) for name in dict.fromkeys(cfg.mission.feeds)]  # each once, as `run` opens them
    return found
