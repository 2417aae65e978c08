"""The simulated camera: the true poses in, the frame a real camera would deliver out (or None,
dropped), stamped with its capture time."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mission.vision.camera import CameraModel, Frame
from mission.vision.frames import quaternion_matrix
from mission.vision.layout import MarkerLayout
from sim.camera.render import Poses, other_poses, render, true_marker_pose
from sim.camera.sensor import Sensor, image_motion_px

MIN_DEPTH_M = 0.2  # [m] a deck nearer the camera's plane than this (or behind it) is not captured


@dataclass
class SimulatedCamera:
    """``camera`` (its intrinsics and mount) looking at ``layout`` through ``sensor``; ``others``:
    the deck's other markers (a team's other slots'), each a layout and its centre's NED offset
    [m] from ``layout``'s, rendered too (:func:`sim.camera.render.other_poses`)."""

    camera: CameraModel
    layout: MarkerLayout
    sensor: Sensor = field(default_factory=Sensor)
    others: tuple[tuple[MarkerLayout, np.ndarray], ...] = ()

    def capture(self, poses: Poses, capture_t_s: float, relative_velocity_ned_m_s=(0.0, 0.0, 0.0)) -> Frame | None:
        """The frame exposed at ``capture_t_s`` [s] from the true ``poses``; the deck's velocity
        relative to the vehicle ``relative_velocity_ned_m_s`` [m/s] NED blurs it over the
        exposure. None: the frame was dropped, or the deck is nearer the camera's plane than
        :data:`MIN_DEPTH_M` (or behind it): out of view, and level with the lens its blur is
        unbounded (a vehicle standing on a marker at the deck's height)."""
        marker = true_marker_pose(self.camera, poses)
        if not marker.deck_in_cam_m[2] >= MIN_DEPTH_M:
            return None
        rotation_ned_cam = quaternion_matrix(poses.attitude_q_wxyz) @ self.camera.mount.rotation_body_cam
        velocity_cam = rotation_ned_cam.T @ np.asarray(relative_velocity_ned_m_s, float)
        blur = image_motion_px(self.camera, marker, velocity_cam, self.sensor.model.exposure_s)
        others = other_poses(self.camera, poses, self.others)
        image = self.sensor.expose(render(self.camera, self.layout, marker, others=others), blur)
        return None if image is None else Frame(image, capture_t_s)
