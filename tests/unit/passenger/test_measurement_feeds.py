"""A new measurement feed reaches the passenger's step through the seam alone.

Everything of the feed lives in this file, as a new feed's modules would: its reading
(``MarkerFix``, a camera's relative position of the deck's marker, stamped at capture), its
flight side (``ToyCamera``, a :class:`mission.interfaces.MeasurementSource` over the fake world),
its simulated sensor (``ToySensor``, over :class:`sim.batch.recovery.World`) and its pure consumer
(``marker_offset``, what a phase would read). The flight loop (``MissionController``), the CLI's
wiring (``mission.cli.run``) and the simulation (``World``) are used as they are; the two
registries (entry points ``marsupial.feeds`` and ``marsupial.sensors``) are read with this
file's names standing in for ``pyproject.toml``'s lines.
"""
from __future__ import annotations

import tomllib
from dataclasses import dataclass

import numpy as np
import pytest

from mission.cli import run as run_cli
from mission.cli.subcommands import entry_points
from mission.config.schema import load_config, with_overrides
from mission.controller import MissionController
from mission.errors import ConfigError
from mission.passenger.inputs import PassengerInputs
from mission.passenger.step import PassengerStep, StepResult
from mission.phases import Measurement, MissionState, Observation, Phase
from mission.time.clock import ManualClock
from sim.batch import sensors as sim_sensors
from sim.batch.recovery import World, configured
from tests.conftest import CONFIGS, ROOT
from tests.support.fake_vehicle import FakeWorld

LATENCY_S = 0.05  # from capture to the reading's arrival [s]
EVERY = 3  # a reading every third poll (a camera slower than the loop)


@dataclass(frozen=True)
class MarkerFix(Measurement):
    """The deck marker's position less the vehicle's at capture [m] NED."""

    offset_ned_m: np.ndarray


def marker_offset(obs: Observation) -> tuple[np.ndarray, float] | None:
    """The pure consumer: the newest fix's offset [m] NED and its age [s] at the tick (None: no fix yet)."""
    fix = obs.measurements.latest(MarkerFix)
    return None if fix is None else (fix.offset_ned_m, fix.age_s(obs.t_s))


class ToyCamera:
    """The flight side: reads the fake world's carrier and vehicle (the 'pixels') and returns a
    fix every ``EVERY`` polls, captured ``LATENCY_S`` before the poll (the fake world moves
    linearly, so the position at capture is the present one less velocity x latency: here the
    present one, exactly, when both stand still, else within the test's tolerance)."""

    def __init__(self, world: FakeWorld) -> None:
        self.world, self.polls, self.closed = world, 0, False
        self.sent: list[MarkerFix] = []

    def poll(self, t_s: float) -> list[MarkerFix]:
        self.polls += 1
        if self.polls % EVERY:
            return []
        fix = MarkerFix(t_s - LATENCY_S, self.world.carrier_ned_m - self.world.vehicle_ned_m)
        self.sent.append(fix)
        return [fix]

    def close(self) -> None:
        self.closed = True


class BrokenFeed:
    """A feed whose every poll raises (a camera driver's fault)."""

    def __init__(self) -> None:
        self.polls = 0

    def poll(self, t_s: float) -> list[MarkerFix]:
        self.polls += 1
        raise OSError("camera unplugged")

    def close(self) -> None:
        pass


class ToySensor:
    """The simulated world's sensor: the true offset of the carrier from the vehicle."""

    def __init__(self, world: World) -> None:
        self.world, self.polls = world, 0
        self.sent: list[MarkerFix] = []

    def poll(self, t_s: float) -> list[MarkerFix]:
        self.polls += 1
        if self.polls % EVERY:
            return []
        fix = MarkerFix(t_s, self.world.carrier.position - self.world.vehicle.true_position)
        self.sent.append(fix)
        return [fix]

    def close(self) -> None:
        pass


class Watched:
    """The passenger's own step, its every observation kept (the step itself unchanged)."""

    def __init__(self, step: PassengerStep) -> None:
        self.step, self.seen = step, []

    def __call__(self, state: MissionState, inputs: PassengerInputs) -> StepResult:
        result = self.step(state, inputs)
        self.seen.append(result.observation)
        return result


def assert_every_fix_reached_the_step_once(sent: list[MarkerFix], seen: list[Observation]) -> None:
    """Each reading is among the ``new`` of exactly one observation, in order, and between
    readings the consumer reads the last one (its age growing)."""
    arrived = [m for obs in seen for m in obs.measurements.arrived(MarkerFix)]
    assert len(sent) > 10 and arrived == sent
    held = [marker_offset(obs) for obs in seen]
    first = next(i for i, h in enumerate(held) if h is not None)
    assert all(h is None for h in held[:first]) and all(h is not None for h in held[first:])
    ages = [h[1] for h in held[first:] if h is not None]
    assert min(ages) >= 0.0 and max(ages) < (EVERY + 1) * (seen[1].t_s - seen[0].t_s) + LATENCY_S


def test_a_feed_reaches_the_step_of_the_flight_loop(caplog):
    """Handed to MissionController as it is: every fix is in the observation of the tick that
    polled it, the consumer reads the offset the camera saw, and the mission flies as before; a
    feed that raises beside it gives nothing, is logged once and stops neither the loop nor the
    other feed."""
    cfg = load_config(CONFIGS / "demo.toml")
    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(cfg.scenario.target, dtype=float))
    camera, broken = ToyCamera(world), BrokenFeed()
    controller = MissionController(cfg, world, world.feed, clock, publisher=world, command_thread=False,
                                   sources=[broken, camera])
    controller.step = watched = Watched(controller.step)  # type: ignore[assignment]
    outcome = controller.run()
    assert outcome.ok, (outcome.reason, outcome.detail)
    assert camera.polls == broken.polls == controller.ticks == len(watched.seen)
    assert sum("camera unplugged" in r.getMessage() for r in caplog.records) == 1
    assert_every_fix_reached_the_step_once(camera.sent, watched.seen)
    assert any(obs.measurements.arrived(MarkerFix) and obs.vehicle is not None and obs.vehicle.armed
               for obs in watched.seen)  # fixes arrived in flight, not only before arming
    for obs in watched.seen:
        for fix in obs.measurements.arrived(MarkerFix):
            assert obs.t_s - fix.capture_t_s == pytest.approx(LATENCY_S)  # stamped at capture, not arrival


def test_a_feed_reaches_the_step_of_the_simulation():
    """Handed to World as it is: the sensor measures the simulated truth, every fix is in the
    observation of its tick, and a branched world's sensor measures the branch."""
    cfg = load_config(CONFIGS / "demo.toml")
    world = World(cfg, configured(), sensors=[ToySensor])
    world.step = watched = Watched(world.step)  # type: ignore[assignment]
    world.run(lambda w: w.k >= 250)
    sensor = world.sources[0]
    assert isinstance(sensor, ToySensor) and sensor.world is world
    assert_every_fix_reached_the_step_once(sensor.sent, watched.seen)
    assert world.state.phase not in (Phase.ABORT, Phase.PREFLIGHT)
    last = marker_offset(watched.seen[-1])
    assert last is not None and np.linalg.norm(last[0]) < 50.0
    branch = world.copy()
    copied = branch.sources[0]
    assert isinstance(copied, ToySensor) and copied.world is branch and copied is not sensor


def open_toy_camera(cfg, session, clock, link=None) -> ToyCamera:
    """A feed's opener as ``marsupial run`` calls it (the fake world stands in for the pixels)."""
    return ToyCamera(FakeWorld(ManualClock(), target_ned_m=np.zeros(3)))


def test_the_registries_name_the_feed_and_its_sensor(monkeypatch):
    """``mission.feeds = ["marker"]``: the run's wiring finds the feed's opener and the simulation
    the sensor of the same name, both in the entry points; a name registered on neither side is
    refused naming the field before anything is opened."""
    registered = {"marsupial.feeds": {"marker": f"{__name__}:open_toy_camera"},
                  "marsupial.sensors": {"marker": f"{__name__}:ToySensor"}}
    monkeypatch.setattr(run_cli, "entry_points", lambda group: registered.get(group, {}))
    monkeypatch.setattr(sim_sensors, "entry_points", lambda group: registered.get(group, {}))
    cfg = with_overrides(load_config(CONFIGS / "demo.toml"), {"mission.feeds": ["marker"]})
    assert run_cli.feed_openers(cfg) == {"marker": f"{__name__}:open_toy_camera"}
    assert sim_sensors.sensors_for(cfg) == [ToySensor]
    world = World(cfg, configured())
    assert [type(s) for s in world.sources] == [ToySensor]
    unknown = with_overrides(cfg, {"mission.feeds": ["lidar"]})
    with pytest.raises(ConfigError, match="mission.feeds"):
        run_cli.check_config(unknown)
    with pytest.raises(ConfigError, match="mission.feeds"):
        World(unknown, configured())


def test_the_registries_are_read_from_the_source_tree():
    """Run from the source tree, the entry points are pyproject.toml's as written (a feed or a
    sensor added there is found without reinstalling), in declaration order."""
    table = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]
    for group in ("marsupial.commands", run_cli.FEEDS_GROUP, sim_sensors.SENSORS_GROUP):
        assert list(entry_points(group).items()) == list(table.get(group, {}).items())


def test_a_feed_that_only_the_simulation_has_is_refused_naming_it():
    """``marker_rendered`` has a simulated sensor and no flight feed (the flight's ``marker`` reads
    the camera's frames, :mod:`mission.cli.marker`): ``marsupial run`` refuses it naming
    ``mission.feeds`` and saying it is simulation-only; configs/relnav.toml's ``marker`` it opens,
    and ``rangefinder`` beside it (:mod:`mission.cli.rangefinder`), each alone too."""
    from mission.cli.run import feed_openers
    from mission.config.schema import load_config
    from mission.errors import ConfigError
    from tests.conftest import CONFIGS

    relnav = load_config(CONFIGS / "relnav.toml")
    with pytest.raises(ConfigError, match=r"mission\.feeds.*marker_rendered: a simulated sensor only"):
        feed_openers(with_overrides(relnav, {"mission.feeds": ["marker_rendered"]}))
    assert feed_openers(relnav) == {"marker": "mission.cli.marker:open_feed",  # the vehicle's DISTANCE_SENSOR
                                    "rangefinder": "mission.cli.rangefinder:open_feed"}
    for name in ("marker", "rangefinder"):
        alone = with_overrides(relnav, {"mission.feeds": [name]})
        assert feed_openers(alone) == {name: f"mission.cli.{name}:open_feed"}
