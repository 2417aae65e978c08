"""``[vision]``: the passenger's downward camera and the marker on the deck (docs/vision.md). Part
of the schema in :mod:`mission.config.schema`; the runtime models are built from it in
:mod:`mission.model` (the detector) and :mod:`sim.camera.sensor` (the simulated sensor)."""
from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import Field, field_validator

from mission.config.fields import Path_, Section, printable
from mission.errors import ConfigError
from mission.vision.layout import TAG_BITS

APRILTAG_36H11_TAGS = 587  # ids 0..586

Offset = Annotated[float, Field(ge=-2, le=2)]
Angle = Annotated[float, Field(ge=-180, le=180)]


class VisionSection(Section):
    """The camera (simulated or real) and the AprilTag 36h11 marker layout."""

    layout: Literal["single", "bundle"] = Field("bundle",
        description=("[-] `single`: one tag on the deck centre; `bundle`: a small tag on the deck centre and the big "
                     "one just ahead of it (the last half metre sees the small one)"))
    tag_size_m: float = Field(0.5, gt=0.02, le=5,
        description="[m] side of the big (or only) tag's black square, as printed")
    small_tag_size_m: float = Field(0.1, gt=0.01, le=1,
        description="[m] side of the bundle's small tag's black square, as printed")
    tag_id: int = Field(0, ge=0, lt=APRILTAG_36H11_TAGS, description="[-] the big (or only) tag's AprilTag 36h11 id")
    small_tag_id: int = Field(1, ge=0, lt=APRILTAG_36H11_TAGS, description="[-] the bundle's small tag's id")
    marker_offset_ned_m: list[Annotated[float, Field(ge=-100, le=100)]] | None = Field(None,
        description=("[m] NED offset of the marker's centre (the deck centre the detector measures) from the carrier's "
                     "reported position; unset: at the dock point (`mission.dock_offset_ned_m`, right when the "
                     "vehicle rides on the deck). A hover ride rides over the deck: set the deck, e.g. [0, 0, 0], "
                     "and the camera sees the marker while riding"))
    width_px: int = Field(640, ge=160, le=4096, description="[px] image width (without a calibration file)")
    height_px: int = Field(480, ge=120, le=4096, description="[px] image height (without a calibration file)")
    hfov_deg: float = Field(80.0, ge=30, le=120,
        description="[deg] horizontal field of view of the ideal pinhole (without a calibration file)")
    calibration_file: Path_ | None = Field(None,
        description=("[path] a real camera's calibration (OpenCV YAML/XML/JSON, plain JSON or ROS camera_info); "
                     "replaces width_px, height_px and hfov_deg"))
    mount_offset_body_m: list[Offset] = Field(
        [0.0, 0.0, 0.0], description="[m] the camera's optical centre in the vehicle's body frame (FRD)")
    mount_rpy_deg: list[Angle] = Field(
        [0.0, 0.0, 0.0], description=("[deg] roll, pitch, yaw of the camera from the nominal downward mount (optical "
                                      "axis down, image top forward)"))
    rate_hz: float = Field(30.0, ge=1, le=120, description="[Hz] frames a second")
    log_rate_hz: float = Field(10.0, ge=0, le=120,
        description=("[Hz] frames a second the marker feed writes to flight.mcap (JPEG, with the camera's calibration "
                     "and the detected corners); 0: none"))
    latency_s: float = Field(0.08, ge=0, le=0.5,
        description="[s] from a frame's exposure to its delivery: its capture time is the delivery's minus this")
    max_tilt_deg: float = Field(30.0, gt=0, le=80,
        description="[deg] flip gate: a pose whose deck normal is further than this from the vertical is rejected")
    max_reprojection_px: float = Field(2.0, gt=0, le=20,
        description="[px] a pose whose RMS corner reprojection error is above this is rejected")
    noise_sigma: float = Field(2.0, ge=0, le=50,
        description="[grey levels] simulated camera: standard deviation of the read noise (0-255 scale)")
    exposure_s: float = Field(0.005, ge=0, le=0.1,
        description="[s] simulated camera: exposure time (motion blur = image speed x this)")
    dropout_probability: float = Field(0.02, ge=0, le=1,
        description="[-] simulated camera: the chance a frame is lost")

    _calibration_printable = field_validator("calibration_file")(lambda v: v if v is None else printable(v))


def marker_offset_ned_m(v: VisionSection, dock_offset_ned_m: list[float]) -> list[float]:
    """[m] NED, the marker's centre from the carrier's reported position: ``vision.marker_offset_ned_m``,
    or the dock point ``dock_offset_ned_m`` (``mission.dock_offset_ned_m``) when it is unset. The one
    place both the controller (the estimator) and the simulators (the rendered deck) read it from."""
    return list(v.marker_offset_ned_m if v.marker_offset_ned_m is not None else dock_offset_ned_m)


def check_vision(v: VisionSection, decision_height_m: float, dock_offset_ned_m: list[float]) -> None:
    """The marker can be seen where it matters: the bundle's two tags differ, and the tag that
    serves the last metres (the small one of a bundle, else the only one) fits wholly in the image
    at ``recovery.decision_height_m`` (the camera that far above the dock point
    ``dock_offset_ned_m`` [m] NED, the marker where :func:`marker_offset_ned_m` puts it, less the
    mount's down offset). Skipped with a calibration file (its field of view is only known once it
    is read)."""
    for name in ("mount_offset_body_m", "mount_rpy_deg", "marker_offset_ned_m"):
        if getattr(v, name) is not None and len(getattr(v, name)) != 3:
            raise ConfigError(f"vision.{name}", getattr(v, name), "must have 3 components")
    marker_below_dock_m = marker_offset_ned_m(v, dock_offset_ned_m)[2] - dock_offset_ned_m[2]
    if v.layout == "bundle":
        if v.small_tag_id == v.tag_id:
            raise ConfigError("vision.small_tag_id", v.small_tag_id, "must differ from vision.tag_id")
        if not v.small_tag_size_m < v.tag_size_m:
            raise ConfigError("vision.small_tag_size_m", v.small_tag_size_m,
                              f"must be smaller than vision.tag_size_m = {v.tag_size_m:g}")
    if v.calibration_file is not None:
        return
    name, size = ("vision.small_tag_size_m", v.small_tag_size_m) if v.layout == "bundle" else ("vision.tag_size_m", v.tag_size_m)
    height = decision_height_m + marker_below_dock_m - v.mount_offset_body_m[2]
    if not height > 0 and marker_below_dock_m < 0:
        raise ConfigError("vision.marker_offset_ned_m", v.marker_offset_ned_m,
                          f"the marker is {-marker_below_dock_m:g} m above the dock point: at "
                          f"recovery.decision_height_m = {decision_height_m:g} m the camera is not above it")
    half_h = math.tan(math.radians(v.hfov_deg) / 2)
    span = 2 * height * min(half_h, half_h * v.height_px / v.width_px)  # the image's short side on the deck
    printed = size * (TAG_BITS + 2) / TAG_BITS
    if not printed < span:
        raise ConfigError(name, size, f"never wholly in view at recovery.decision_height_m = {decision_height_m:g} m: "
                          f"printed with its margin it is {printed:.2f} m, the image's short side spans {span:.2f} m "
                          "there (a smaller tag, a wider vision.hfov_deg or vision.layout = \"bundle\")")
