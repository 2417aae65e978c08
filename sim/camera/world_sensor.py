"""The deck marker as a sensor of the in-process mission simulation (:class:`sim.batch.recovery.World`,
feed name ``marker``): the passenger's downward camera of ``[vision]`` looking at the carrier's
deck from the world's truth, each reading a :class:`~mission.phases.measurements.RelativePosition`
(the deck centre less the vehicle, NED [m]) stamped at capture and delivered ``vision.latency_s``
later.

Two ways to measure, chosen by the entry point (``pyproject.toml``, ``marsupial.sensors``):

- ``marker`` (:func:`modelled`): the detection-error model fitted to the real detector
  (:class:`sim.camera.error_model.ModelledDetector`, ``FITTED``; no image; fast enough for batches);
- ``marker_rendered`` (:func:`rendered`): a frame rendered from the true poses with the
  sensor's noise, blur and dropouts (:class:`sim.camera.simulated.SimulatedCamera`) and the real
  detector and pose (:class:`mission.vision.detect.MarkerDetector`): ~5-10 ms a frame.

The vehicle's attitude is the one its acceleration gives a multicopter (the mock's ATTITUDE:
:func:`sim.vehicle.physics.multicopter.attitude_quaternion`); the deck is level
at the carrier's yaw, its centre (the marker's) at the carrier's reference point plus
``vision.marker_offset_ned_m`` (by default ``mission.dock_offset_ned_m``, the dock point, where the
vehicle sits when docked). Captures happen on
the world's ticks at ``vision.rate_hz`` at most; every draw is seeded by the scenario's seed.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from mission.config.vision import marker_offset_ned_m
from mission.model import vision_detector
from mission.phases.measurements import Measurement, RelativePosition
from mission.vision.measurement import RelativeMeasurement
from sim.batch.sensors import CaptureGrid
from sim.camera.error_model import FITTED, ModelledDetector
from sim.camera.render import Poses
from sim.camera.sensor import Sensor, sensor_model
from sim.camera.simulated import SimulatedCamera
from sim.vehicle.physics.multicopter import attitude_quaternion

if TYPE_CHECKING:
    from sim.batch.recovery import World

SEED_OFFSET = 7717  # the marker's stream, apart from the other seeded streams of the scenario's seed


class WorldMarker:
    """The world's marker sensor: ``measure(poses, t)`` the measurement of one capture (None: not
    seen); a :class:`mission.interfaces.MeasurementSource`."""

    def __init__(self, world: World, measure: Callable[[Poses, float], RelativeMeasurement | None]) -> None:
        v = world.cfg.vision
        self.world, self.measure = world, measure
        self.grid: CaptureGrid[RelativePosition] = CaptureGrid(1.0 / v.rate_hz, v.latency_s)
        self.captured = 0  # frames taken
        self.seen = 0  # frames that gave a measurement
        outages = world.cfg.world.marker_outages
        self.outages = outages if outages.fraction > 0 else None
        self.outage_rng = np.random.default_rng(world.scenario.seed + SEED_OFFSET + 1)
        self.blind_until_s = -math.inf  # [s] the end of the current outage
        self.checked_s: float | None = None  # [s] when an outage last could begin

    def poses(self, t_s: float) -> Poses:
        """The truth at ``t_s`` [s]: the vehicle tilted as its acceleration tilts a multicopter
        (:func:`sim.vehicle.physics.multicopter.attitude_quaternion`: a downward camera looks away
        from where the vehicle accelerates), the marker on the deck (the carrier's reference point
        plus ``vision.marker_offset_ned_m``, by default the dock point)."""
        kin = self.world.vehicle.kin
        cfg = self.world.cfg
        deck = self.world.carrier.true_at(t_s)[0] + np.asarray(marker_offset_ned_m(cfg.vision, cfg.mission.dock_offset_ned_m), float)
        return Poses(self.world.vehicle.true_position, np.array(attitude_quaternion(kin)), deck, self.world.carrier.yaw_rad)

    def poll(self, t_s: float) -> list[Measurement]:
        """Capture if a frame is due at ``t_s`` [s]; deliver what is ``latency_s`` old."""
        if self.grid.due(t_s):
            self.captured += 1
            m = None if self._blind(t_s) else self.measure(self.poses(t_s), t_s)
            if m is not None:
                self.seen += 1
                self.grid.hold(RelativePosition(capture_t_s=t_s, offset_ned_m=np.asarray(m.deck_rel_ned_m, float),
                                                sigma_m=float(m.sigma_m), marker=int(m.tag_ids[0])))
        return list(self.grid.deliver(t_s))

    def _blind(self, t_s: float) -> bool:
        """In an outage at ``t_s`` [s] (``world.marker_outages``): spells of a length uniform in
        [min_s, max_s] begin at a rate (Poisson) that makes them ``fraction`` of the time."""
        o = self.outages
        if o is None:
            return False
        dt = 0.0 if self.checked_s is None else t_s - self.checked_s
        self.checked_s = t_s
        if t_s < self.blind_until_s:
            return True
        mean_s = 0.5 * (o.min_s + o.max_s)
        rate = o.fraction / ((1.0 - o.fraction) * mean_s)  # [1/s] outages begin, while not in one
        if self.outage_rng.random() < -math.expm1(-rate * dt):
            self.blind_until_s = t_s + self.outage_rng.uniform(o.min_s, o.max_s)
            return True
        return False

    def close(self) -> None:
        self.grid.clear()


def modelled(world: World) -> WorldMarker:
    """The marker through the fitted detection-error model (feed ``marker``)."""
    detector = vision_detector(world.cfg)
    model = ModelledDetector(detector.camera, detector.layout, FITTED, seed=world.scenario.seed + SEED_OFFSET)
    return WorldMarker(world, model.measure)


def rendered(world: World) -> WorldMarker:
    """The marker rendered, exposed and detected (feed ``marker_rendered``)."""
    detector = vision_detector(world.cfg)
    camera = SimulatedCamera(detector.camera, detector.layout,
                             Sensor(sensor_model(world.cfg.vision), seed=world.scenario.seed + SEED_OFFSET))

    def measure(poses: Poses, t_s: float) -> RelativeMeasurement | None:
        frame = camera.capture(poses, t_s)
        return None if frame is None else detector.measure(frame.image, t_s, poses.attitude_q_wxyz)

    return WorldMarker(world, measure)
