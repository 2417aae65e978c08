"""The sensor's effects on a rendered frame: motion blur along the image motion during the
exposure, Gaussian read noise, and dropped frames, all from a seeded generator."""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from mission.config.vision import VisionSection
from mission.model import derived
from mission.vision.camera import CameraModel
from mission.vision.measurement import MarkerPose


NOISE_BANK_FRAMES = 4  # frames of read noise drawn once, windows of which make each frame's


@dataclass(frozen=True)
class SensorModel:
    """noise_sigma: the read noise's standard deviation [grey levels, 0-255]; exposure_s: the
    exposure time [s] (blur length = image speed x exposure); dropout_probability: the chance a
    frame is lost [0-1]; rate_hz: frames a second; latency_s: from exposure to the frame's
    delivery [s] (the consumer applies it: a frame carries its capture time). No defaults: they
    are the ``[vision]`` section's (:func:`sensor_model`)."""

    noise_sigma: float
    exposure_s: float
    dropout_probability: float
    rate_hz: float
    latency_s: float


def sensor_model(section: VisionSection | None = None, **changed: float) -> SensorModel:
    """The simulated sensor of the configuration's ``[vision]`` section (None: the schema's
    defaults), with the fields named in ``changed`` set to their values."""
    return replace(derived(SensorModel, section if section is not None else VisionSection()), **changed)


@dataclass
class Sensor:
    """A camera's sensor with its own seeded random stream."""

    model: SensorModel = field(default_factory=sensor_model)
    seed: int = 0

    def __post_init__(self) -> None:
        self._rng = np.random.default_rng(self.seed)
        self._bank: np.ndarray | None = None  # the read noise drawn once, NOISE_BANK_FRAMES frames of it, scaled

    def expose(self, ideal: np.ndarray, blur_px: np.ndarray | None = None) -> np.ndarray | None:
        """The frame the sensor delivers from the ideal one: None when dropped; else blurred
        along ``blur_px`` (2,) (the image motion during the exposure [px]) and noisy, uint8."""
        if self._rng.random() < self.model.dropout_probability:
            return None
        frame = ideal.astype(np.float32)
        if blur_px is not None and np.hypot(*blur_px) >= 1.0:
            import cv2  # (here, not at the top: a mock vehicle without a camera imports this module)

            frame = cv2.filter2D(frame, -1, line_kernel(blur_px))
        if self.model.noise_sigma > 0:
            frame += self._read_noise(frame.shape)
        frame += np.float32(0.5)
        np.clip(frame, 0, 255, out=frame)
        return frame.astype(np.uint8)

    def _read_noise(self, shape: tuple[int, ...]) -> np.ndarray:
        """One frame's read noise [grey levels]: a window of ``shape`` at a seeded random place
        in a bank of :data:`NOISE_BANK_FRAMES` frames of independent normals (times the noise's
        sigma), drawn at the first frame. Each pixel's noise is Gaussian with the model's sigma,
        independent of its neighbours'; two frames' windows are the bank shifted by a random
        number of pixels, so a pixel's noise is not its noise in the last frame (why a bank and
        not fresh draws: docs/testing.md, thirteenth session)."""
        size = int(np.prod(shape))
        if self._bank is None or self._bank.size < NOISE_BANK_FRAMES * size:
            self._bank = self._rng.standard_normal(NOISE_BANK_FRAMES * size, dtype=np.float32)
            self._bank *= np.float32(self.model.noise_sigma)
        start = int(self._rng.integers(0, self._bank.size - size + 1))
        return self._bank[start:start + size].reshape(shape)


def line_kernel(blur_px: np.ndarray) -> np.ndarray:
    """A normalised line kernel along ``blur_px`` (dx, dy) [px], centred."""
    length = float(np.hypot(*blur_px))
    half = int(np.ceil(length / 2))
    size = 2 * half + 1
    kernel = np.zeros((size, size), np.float32)
    steps = max(int(np.ceil(length * 2)), 2)
    for s in np.linspace(-0.5, 0.5, steps):
        x, y = half + s * blur_px[0], half + s * blur_px[1]
        kernel[int(round(y)), int(round(x))] += 1.0
    return kernel / kernel.sum()


def image_motion_px(camera: CameraModel, marker: MarkerPose, velocity_cam_m_s: np.ndarray, exposure_s: float) -> np.ndarray:
    """How far the deck centre moves in the image during one exposure [px] (dx, dy): the deck's
    velocity relative to the camera ``velocity_cam_m_s`` (3,) in camera axes [m/s] times
    ``exposure_s`` [s], through the pinhole at the deck's depth (the camera's rotation rate aside)."""
    x, y, z = marker.deck_in_cam_m
    vx, vy, vz = np.asarray(velocity_cam_m_s, float)
    fx, fy = camera.matrix[0, 0], camera.matrix[1, 1]
    du = fx * (vx * z - x * vz) / z ** 2
    dv = fy * (vy * z - y * vz) / z ** 2
    return np.array([du, dv]) * exposure_s
