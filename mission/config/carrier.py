"""The carrier's configuration: ``[carrier]`` (the carrier-side controller, ``marsupial
carrier``) and its backends ``[carrier.mavlink]`` (a PX4 rover or boat) and ``[carrier.ros2]``
(a ROS 2 robot over Zenoh). Part of the schema in :mod:`mission.config.schema`."""
from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from mission.config.fields import MAX_URL_CHARS, Path_, Section, check_mavlink_url
from mission.errors import ConfigError


class CarrierMavlinkSection(Section):
    """``carrier.backend = "mavlink"``: a PX4 rover or boat, flown through the passenger's link code."""

    url: str = Field("udpin:127.0.0.1:14541", max_length=MAX_URL_CHARS,
                     description="PX4 instance i sends its onboard link to 14540 + i")
    target_system: int | None = Field(None, ge=1, le=255, description="the rover's MAV_SYS_ID (PX4 instance i: i + 1)")
    source_system: int | None = Field(None, ge=1, le=255, description="our system id; default: target_system, "
                                      "or 1 (PX4 registers an onboard controller of its own system only)")
    source_component: int = Field(191, ge=1, le=255)
    signing_key_file: Path_ | None = None
    heartbeat_timeout_s: float = Field(3.0, gt=0, le=30)
    prestream_s: float = Field(1.0, ge=0.2, description="[s] setpoints streamed before OFFBOARD is asked")
    offset_ned_m: list[float] = Field([0.0, 0.0, 0.0], description="[m] the vehicle's local origin in the "
                                      "shared frame (added to LOCAL_POSITION_NED)")
    shared_origin: list[float] | None = Field(None, description="lat [deg], lon [deg], alt [m] of the shared "
                                              "frame's origin: the offset then comes from the vehicle's EKF origin")

    _url_ok = field_validator("url")(check_mavlink_url)


class CarrierRos2Section(Section):
    """``carrier.backend = "ros2"``: a ROS 2 robot over Zenoh (nav_msgs/Odometry in, geometry_msgs/Twist out, CDR)."""

    key_form: Literal["ros2dds", "rmw_zenoh"] = Field("ros2dds", description="zenoh-bridge-ros2dds keys "
                                                      "('<ns>/odom') or rmw_zenoh keys ('<domain>/<ns>/odom/<type>/<hash>')")
    namespace: str = Field("", pattern=r"^[A-Za-z0-9_/]*$")
    domain_id: int = Field(0, ge=0, le=232)
    odom_topic: str = Field("odom", pattern=r"^[A-Za-z0-9_/]+$")
    cmd_vel_topic: str = Field("cmd_vel", pattern=r"^[A-Za-z0-9_/]+$")
    offset_ned_m: list[float] = Field([0.0, 0.0, 0.0], description="[m] the odom frame's origin in the shared frame")


class CarrierSection(Section):
    """The carrier-side controller (``marsupial carrier``) and its backend."""

    backend: Literal["sim", "mavlink", "ros2"] = "sim"
    rate_hz: float = Field(30.0, ge=5, le=1000)
    max_speed_m_s: float = Field(3.0, gt=0, le=100, description="[m/s] the carrier's top speed (the passenger's "
                                 "feed also gates carrier states against it)")
    passenger_timeout_s: float = Field(
        1.0, gt=0, le=10, description="[s] simulated; a passenger status older than this (or a lost "
        "liveliness token) stops a carrier that is approaching the target")
    state_timeout_s: float = Field(0.5, gt=0, le=10, description="[s] own state older than this stops the carrier")
    p3_margin_m: float = Field(0.5, gt=0, description="[m] the P3 guard keeps the carrier at least b c - margin "
                               "from the target, whatever the passenger does")
    brake_decel_m_s2: float | None = Field(None, gt=0, description="[m/s^2] braking the guard plans with; "
                                           "default safety.carrier_max_accel_m_s2, else 1")
    brake_delay_s: float | None = Field(None, ge=0, le=5, description="[s] the carrier's response delay (command "
                                        "to motion, plus the age of its state) the guard allows for; default 0 for "
                                        "the built-in robot, 0.3 s for a real one (mavlink, ros2)")
    kinematics: Literal["holonomic", "diff_drive", "ackermann"] = "holonomic"
    heading_gain: float = Field(2.0, gt=0, description="[1/s] tracking law: yaw rate per heading error")
    max_yaw_rate_rad_s: float = Field(1.0, gt=0)
    min_speed_fraction: float = Field(0.3, ge=0, le=1, description="Ackermann: speed kept while misaligned")
    wheelbase_m: float = Field(0.3, gt=0)
    max_steer_rad: float = Field(0.5, gt=0, lt=1.5)
    align_on_deck_m: float = Field(0.0, ge=0, le=5, description="[m] largest horizontal shift of the carrier's "
                                   "estimate onto the passenger's while it stands on the deck (before take-off); 0 off")
    speed_ratio_tau_s: float = Field(0.0, ge=0, le=30, description="[s] diff-drive/Ackermann: time constant of the "
                                     "estimate r >= 1 of measured over asked forward speed; the vehicle is asked for v / r "
                                     "(a speed loop that overshoots); 0 off")
    acceleration_tau_s: float = Field(0.0, ge=0, le=5, description="[s] publish the carrier's measured acceleration "
                                      "(its velocity's change, low-passed with this time constant) for the passenger's "
                                      "feed-forward; 0: send none (the passenger predicts it from the carrier law)")
    velocity_bias_tau_s: float = Field(0.0, ge=0, le=60, description="[s] publish the velocity corrected by the "
                                       "low-passed (this time constant) difference between its position's rate and its "
                                       "estimator's velocity (a PX4 rover's EKF position ran 0.1-0.3 m/s faster); 0 off")
    start_accel_m_s2: float = Field(0.0, ge=0, le=100, description="[m/s^2] while the carrier is measured "
                                    "slower than 0.15 m/s, its command's speed grows by at most this (a rover with "
                                    "stiction breaks free at a low command instead of leaping to a high one); 0 off")
    start_yaw_rad: float | None = Field(None, description="[rad] sim backend: initial heading (default: towards the target)")
    mavlink: CarrierMavlinkSection = CarrierMavlinkSection()
    ros2: CarrierRos2Section = CarrierRos2Section()

    @model_validator(mode="after")
    def _vectors(self) -> "CarrierSection":
        for name, v in (("mavlink.offset_ned_m", self.mavlink.offset_ned_m), ("ros2.offset_ned_m", self.ros2.offset_ned_m)):
            if len(v) != 3:
                raise ConfigError(f"carrier.{name}", v, "must have 3 components")
        if self.mavlink.shared_origin is not None and len(self.mavlink.shared_origin) != 3:
            raise ConfigError("carrier.mavlink.shared_origin", self.mavlink.shared_origin, "must be [lat, lon, alt]")
        return self
