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
from typing import TYPE_CHECKING, Any

from mission.cli.subcommands import SENSORS_GROUP, entry_points, load
from mission.config.schema import Config
from mission.errors import ConfigError
from mission.interfaces import MeasurementSource

if TYPE_CHECKING:
    from sim.batch.recovery import World

#: A sensor of the simulated world: the world in, the measurement source that measures it out.
SensorFactory = Callable[["World"], MeasurementSource]


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
