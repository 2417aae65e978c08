"""The passenger's downward camera in simulation: frames rendered from the true poses, for the mock
vehicle (``mock-vehicle --camera``: the vehicle's true position, tilted as its acceleration tilts a
multicopter) and for PX4 SITL
(:mod:`sim.sitl.camera`: SIH's true position and attitude of the passenger and the rover), given as
a :class:`BodyTruth` and a :class:`DeckTruth` (the marker at the carrier's true
reference point plus ``vision.marker_offset_ned_m``, by default the dock point, level at the
carrier's yaw), exposed with the
sensor's noise, blur and dropouts (:class:`sim.camera.simulated.SimulatedCamera`, ``[vision]``),
published at capture on the pair's camera key (:mod:`mission.bus.frames`) for the mission's marker
feed, which runs the detector on the pixels. Captures at ``vision.rate_hz`` on the vehicle's
simulated time, taken in its physics pass (so in lockstep at the same times every run); seeded.
The capture grid is the simulated clock's, ``k / vision.rate_hz`` from t = 0: a frame is taken at
the first physics pass at or after each slot (a slot passed over by a long pass is skipped), so the
capture times are a function of simulated time only, never of when the carrier was first heard.
Until the deck is known (the carrier's first state) each slot is published as a time mark only.
Given a signer (the passenger robot's own key, ``mock-vehicle --zenoh-private-key`` or
``--zenoh-signing-key``), every sample is signed as a real camera node's on a signed bus must be.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import zenoh

from mission.bus.auth import SampleSigner
from mission.bus.frames import camera_key, encode_frame, encode_mark
from mission.bus.session import declare, undeclare
from mission.config.schema import Config
from mission.config.vision import marker_offset_ned_m
from mission.model import vision_detector
from sim.camera.render import Poses, true_marker_pose
from sim.camera.sensor import Sensor, sensor_model
from sim.camera.simulated import MIN_DEPTH_M, SimulatedCamera

SEED_OFFSET = 7717  # the sensor's stream, apart from the vehicle's other seeded streams


@dataclass(frozen=True)
class BodyTruth:
    """The camera's vehicle, true: position ``position_ned_m`` (3,) [m] (any origin shared with the
    :class:`DeckTruth`), attitude ``attitude_q_wxyz`` (4,) body -> NED, velocity
    ``velocity_ned_m_s`` (3,) [m/s] NED."""

    position_ned_m: np.ndarray
    attitude_q_wxyz: np.ndarray
    velocity_ned_m_s: np.ndarray

    @classmethod
    def level(cls, position_ned_m: np.ndarray, yaw_rad: float, velocity_ned_m_s: np.ndarray) -> BodyTruth:
        """A vehicle level at yaw ``yaw_rad`` [rad] (a hover; the mock tilts with its acceleration:
        :func:`sim.vehicle.physics.multicopter.attitude_quaternion`)."""
        half = yaw_rad / 2
        return cls(np.asarray(position_ned_m, float), np.array([math.cos(half), 0.0, 0.0, math.sin(half)]),
                   np.asarray(velocity_ned_m_s, float))


@dataclass(frozen=True)
class DeckTruth:
    """The carrier, true: its reference point ``position_ned_m`` (3,) [m] (the marker lies
    ``vision.marker_offset_ned_m`` from it), velocity ``velocity_ned_m_s`` (3,) [m/s] NED and yaw
    ``yaw_rad`` [rad] (None: its heading of travel)."""

    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    yaw_rad: float | None = None


class CameraPublisher:
    """Renders and publishes a frame when one is due (:meth:`sample`, in the vehicle's physics pass)."""

    def __init__(self, cfg: Config, session: zenoh.Session, pair: str, seed: int, lockstep: bool,
                 signer: SampleSigner | None = None, passenger: str | None = None,
                 others: tuple[Config, ...] = ()) -> None:
        """``cfg``: the camera's passenger's configuration (its marker: the one it looks for);
        ``passenger``: a team passenger's name, its camera on its own key (:func:`camera_key`);
        ``others``: the configurations of the deck's other markers' passengers (a team's other
        slots'), whose markers the frames show as well."""
        detector = vision_detector(cfg)
        self.marker_offset_ned_m = np.asarray(marker_offset_ned_m(cfg.vision, cfg.mission.dock_offset_ned_m), dtype=float)
        neighbours = tuple((vision_detector(c).layout, np.asarray(marker_offset_ned_m(c.vision, c.mission.dock_offset_ned_m),
                                                                  dtype=float) - self.marker_offset_ned_m) for c in others)
        self.camera = SimulatedCamera(detector.camera, detector.layout,
                                      Sensor(sensor_model(cfg.vision), seed=seed + SEED_OFFSET), neighbours)
        self.period_s = 1.0 / cfg.vision.rate_hz
        self.next_s = 0.0  # the next slot's time [s]: k / rate_hz
        self.captured = self.sent = 0
        key = camera_key(pair, passenger)
        self.key, self._signer = key, signer
        # In real time DROP: the put runs in the vehicle's physics pass, which must not wait on the
        # network (a dropped frame is a camera dropout, counted by the feed as a gap). In lockstep
        # BLOCK, as the state streams: a frame Zenoh dropped under load (2 of 3272 in one relnav
        # demo) made two runs of one seed fuse different markers from t = 3.6 s on.
        congestion = zenoh.CongestionControl.BLOCK if lockstep else zenoh.CongestionControl.DROP
        self._pub = declare(f"publisher on {key}", lambda: session.declare_publisher(
            key, congestion_control=congestion, express=True))

    def sample(self, t_s: float, vehicle: BodyTruth, deck: DeckTruth | None) -> None:
        """At time ``t_s`` [s] on the mission's clock, the vehicle's and the carrier's true state
        (``deck`` None: not known yet, no deck to see): capture if a slot of the grid is due."""
        if t_s + 1e-9 < self.next_s:
            return
        # the next slot after t_s on the grid k / rate_hz (not t_s + period: the first capture, at
        # whichever pass first had the deck, would set the phase of every later one)
        self.next_s = (math.floor(t_s / self.period_s + 1e-6) + 1) * self.period_s
        self.captured += 1
        if deck is None:
            self._put(encode_mark(t_s), False)
            return
        q = np.asarray(vehicle.attitude_q_wxyz, dtype=float)
        v_c = np.asarray(deck.velocity_ned_m_s, dtype=float)
        yaw = deck.yaw_rad if deck.yaw_rad is not None else (
            math.atan2(v_c[1], v_c[0]) if math.hypot(v_c[0], v_c[1]) > 1e-6 else 0.0)
        poses = Poses(np.asarray(vehicle.position_ned_m, float), q,
                      np.asarray(deck.position_ned_m, float) + self.marker_offset_ned_m, float(yaw))
        frame = None
        if true_marker_pose(self.camera.camera, poses).deck_in_cam_m[2] >= MIN_DEPTH_M:  # else out of view (and
            relative_v = v_c - np.asarray(vehicle.velocity_ned_m_s, float)  # its blur unbounded)
            frame = self.camera.capture(poses, t_s, relative_v)
        # a dropped or empty frame still marks the time: a lockstep reader knows the stream passed it
        self._put(encode_mark(t_s) if frame is None else encode_frame(frame, q), frame is not None)

    def _put(self, payload: bytes, is_frame: bool) -> None:
        try:
            self._pub.put(payload, attachment=None if self._signer is None else self._signer.attachment(self.key, payload))
            self.sent += is_frame
        except zenoh.ZError:
            pass  # the session is closing

    def close(self) -> None:
        undeclare(self._pub)
