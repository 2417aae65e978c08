"""The relative measurement vision emits: where the deck is from the vehicle, seen in one frame.

Frames (all right-handed, SI units):

- **camera** (OpenCV): origin at the optical centre, x right in the image, y down in the image,
  z along the optical axis (out of the lens).
- **body** (PX4's FRD): origin at the vehicle's reference point (what its local position
  reports), x forward, y right, z down. The camera sits at a configured offset and rotation in it.
- **NED**: the vehicle's local north, east, down axes (PX4's LOCAL_NED orientation). Only the
  *axes* are shared with the vehicle's estimate: a relative vector in NED needs no shared origin.
- **deck** (the carrier's FRD at the deck centre): origin at the deck centre (the marker layout's
  origin), x the carrier's forward, y right, z down (into the deck). A tag lies in the deck's
  z = 0 plane, its printed top towards the deck's forward.

The attitude ``attitude_q_wxyz`` is the rotation body -> NED used to turn the body-frame vector
into NED, as PX4 reports it (Hamilton quaternion, w, x, y, z; 1 0 0 0 the null rotation). The
vector in NED is only as good as that attitude at ``capture_t_s``: an estimator that has a better
attitude for that instant can redo the rotation from ``deck_body_frd_m``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MarkerPose:
    """The deck in the camera frame: ``rotation_cam_deck`` (3, 3) turns a deck-frame vector into
    camera axes; ``deck_in_cam_m`` (3,) is the deck centre in the camera frame [m]. A deck point
    ``p`` [m] is at ``rotation_cam_deck @ p + deck_in_cam_m`` in the camera frame."""

    rotation_cam_deck: np.ndarray
    deck_in_cam_m: np.ndarray


@dataclass(frozen=True)
class RelativeMeasurement:
    """One frame's measurement of the deck centre from the vehicle.

    capture_t_s: when the frame was exposed [s], on the clock of whoever stamped it (the camera
    source or the simulator); latency is the consumer's to apply.
    deck_rel_ned_m (3,): the deck centre minus the vehicle's reference point, in NED axes [m]
    (its z is positive when the deck is below the vehicle).
    covariance_ned_m2 (3, 3): the covariance of ``deck_rel_ned_m`` [m^2], from the detector's
    pixel noise propagated through the pose (a model, see docs/vision.md).
    deck_body_frd_m (3,): the same vector in body FRD axes [m] (no attitude used).
    attitude_q_wxyz (4,): the rotation body -> NED used for ``deck_rel_ned_m``.
    deck_yaw_ned_rad: the deck's forward axis's heading in NED [rad] (0 north, pi/2 east), from
    the marker's orientation and the attitude used.
    tag_ids: the tags whose corners made the pose (sorted).
    reprojection_error_px: RMS distance between the detected corners and the pose's projection
    of them [px].
    marker: the deck's pose in the camera frame (what solvePnP solved).
    """

    capture_t_s: float
    deck_rel_ned_m: np.ndarray
    covariance_ned_m2: np.ndarray
    deck_body_frd_m: np.ndarray
    attitude_q_wxyz: np.ndarray
    deck_yaw_ned_rad: float
    tag_ids: tuple[int, ...]
    reprojection_error_px: float
    marker: MarkerPose

    @property
    def sigma_m(self) -> float:
        """A scalar standard deviation [m]: the square root of the covariance's largest eigenvalue."""
        return float(np.sqrt(np.max(np.linalg.eigvalsh(self.covariance_ned_m2))))

    @property
    def distance_m(self) -> float:
        """The distance from the vehicle to the deck centre [m]."""
        return float(np.linalg.norm(self.deck_rel_ned_m))
