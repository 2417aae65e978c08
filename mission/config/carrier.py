"""The carrier's configuration: ``[carrier]`` (the carrier-side controller, ``marsupial
carrier``) and its backends ``[carrier.mavlink]`` (a PX4 rover or boat) and ``[carrier.ros2]``
(a ROS 2 robot over Zenoh). Part of the schema in :mod:`mission.config.schema`.

:data:`KINDS` is the one list of carrier backends: the configuration's choices, ``--backend``'s
choices, the configuration reference and :mod:`mission.carrier.backends` (which opens them)
derive from it. It lives here, in the pure configuration, so that the schema reads it without
importing the carrier's loop.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from pydantic import Field, field_validator, model_validator

from mission.config.fields import MAX_URL_CHARS, Path_, Section, check_mavlink_url
from mission.errors import ConfigError


@dataclass(frozen=True)
class BackendKind:
    """A kind of carrier robot: its name, what it is (``--help``, the configuration reference),
    whether it is a real vehicle (its response delay, ``REAL_DELAY_S``, is allowed for by the P3
    guard), and the module that drives it."""

    name: str
    summary: str
    real: bool
    module: str


KINDS: dict[str, BackendKind] = {k.name: k for k in (
    BackendKind("sim", "built-in kinematic robot", False, "mission.carrier.backends.sim"),
    BackendKind("mavlink", "PX4 rover/boat over MAVLink", True, "mission.carrier.backends.mavlink"),
    BackendKind("ros2", "ROS 2 robot over Zenoh", True, "mission.carrier.backends.ros2"),
)}

BackendName = Literal.__getitem__(tuple(KINDS))  # the registry's names
MAX_COURSE_LEGS = 100  # legs of carrier.recovery_course


class CarrierMavlinkSection(Section):
    """``carrier.backend = "mavlink"``: a PX4 rover or boat, flown through the passenger's link code."""

    url: str = Field("udpin:127.0.0.1:14541", max_length=MAX_URL_CHARS,
                     description="[-] the carrier vehicle's endpoint (as mavlink.url); PX4 SITL instance i sends to 14540 + i")
    target_system: int | None = Field(None, ge=1, le=255,
        description=("[-] MAVLink system id of the carrier vehicle (PX4 SITL instance i: i + 1); default: the first "
                     "PX4 heard"))
    source_system: int | None = Field(None, ge=1, le=255,
        description="[-] our MAVLink system id on that link (default: target_system, else 1)")
    source_component: int = Field(191, ge=1, le=255, description="[-] our MAVLink component id (191: onboard computer)")
    signing_key_file: Path_ | None = Field(None, description="[-] MAVLink 2 signing key file of the carrier's link")
    heartbeat_timeout_s: float = Field(3.0, gt=0, le=30,
        description="[s] the carrier vehicle counts as lost after this long without HEARTBEAT (stop)")
    prestream_s: float = Field(1.0, ge=0.2, description="[s] setpoints streamed before OFFBOARD is asked")
    offset_ned_m: list[float] = Field([0.0, 0.0, 0.0], description="[m] the vehicle's local origin in the "
                                      "shared frame (added to LOCAL_POSITION_NED)")
    shared_origin: list[float] | None = Field(None,
        description=("[deg, deg, m] lat, lon, alt AMSL of the shared frame's origin; when set the offset comes from "
                     "the vehicle's EKF origin (GPS_GLOBAL_ORIGIN)"))

    stand: Literal["position", "creep"] = Field("position",
        description=("[-] how the vehicle is told to stand while its command is a stop: `position`: once it is at rest "
                     "(below stand_speed_m_s) a position setpoint at the point where it came to rest, which PX4 holds "
                     "(bench/px4_rover_stand.py: 0.4 m in 70 s); `creep`: a 1 mm/s velocity along its own heading, on "
                     "which PX4's SIH rover crept or drifted 1.9-2.2 m in 70-80 s"))
    stand_speed_m_s: float = Field(0.1, gt=0, le=1.0,
        description=("[m/s] a stopped vehicle slower than this is at rest (a diff-drive or Ackermann one by its forward "
                     "speed: its estimator's sideways speed is no motion): where it is then is held (stand = position)"))

    _url_ok = field_validator("url")(check_mavlink_url)


class CarrierRos2Section(Section):
    """``carrier.backend = "ros2"``: a ROS 2 robot over Zenoh (nav_msgs/Odometry in, geometry_msgs/Twist or TwistStamped out, CDR)."""

    key_form: Literal["ros2dds", "rmw_zenoh"] = Field("ros2dds",
        description=("[-] `ros2dds` (zenoh-bridge-ros2dds: `<ns>/odom`) or `rmw_zenoh` "
                     "(`<domain>/<ns>/odom/<type>/<hash>`)"))
    namespace: str = Field("", pattern=r"^[A-Za-z0-9_/]*$", description="[-] ROS namespace of the robot's topics")
    domain_id: int = Field(0, ge=0, le=232, description="[-] ROS_DOMAIN_ID (rmw_zenoh keys start with it)")
    odom_topic: str = Field("odom", pattern=r"^[A-Za-z0-9_/]+$",
        description="[-] nav_msgs/Odometry topic (ENU, REP 103) the carrier reads")
    cmd_vel_topic: str = Field("cmd_vel", pattern=r"^[A-Za-z0-9_/]+$",
        description="[-] velocity command topic (body FLU) the carrier commands")
    cmd_vel_type: Literal["Twist", "TwistStamped"] = Field("Twist",
        description=("[-] the command's type: `Twist` (geometry_msgs/msg/Twist) or `TwistStamped` (what ros2_control's "
                     "diff_drive_controller takes since Jazzy)"))
    rmw_attachment: Literal["current", "legacy"] = Field("current",
        description=("[-] rmw_zenoh attachment sent: `current` (rmw_zenoh_cpp Jazzy >= 0.2.4, Humble >= 0.1.2, Kilted, "
                     "Rolling) or `legacy` (labelled, Jazzy <= 0.2.3); both are read"))
    node_name: str = Field("marsupial_carrier", pattern=r"^[A-Za-z_][A-Za-z0-9_]*$",
        description="[-] ROS node name the carrier announces in rmw_zenoh's graph (liveliness tokens)")
    offset_ned_m: list[float] = Field([0.0, 0.0, 0.0], description="[m] the odom frame's origin in the shared frame")


class CarrierSection(Section):
    """The carrier-side controller (``marsupial carrier``) and its backend."""

    backend: BackendName = Field("sim", description="[-] the carrier robot `marsupial carrier` drives: " + ", ".join(  # type: ignore[valid-type]
        f"`{k.name}` ({k.summary})" for k in KINDS.values()))
    rate_hz: float = Field(30.0, ge=5, le=1000,
        description=("[Hz] carrier controller's tick and publish rate (the built-in robot integrates at it; simulated "
                     "time)"))
    max_speed_m_s: float = Field(3.0, gt=0, le=100,
        description="[m/s] carrier speed limit in the law's command (with safety.carrier_max_speed_m_s)")
    separation_speed_m_s: float = Field(0.0, ge=0, le=100,
        description=("[m/s] the most speed the carrier's approach has within separation_room_m of the separation "
                     "distance b c (its own distance to the target, as the law measures it), so that a stop at the "
                     "separation stops it short; its speed limit falls to it at separation_decel_m_s2; 0 off"))
    separation_decel_m_s2: float = Field(0.2, gt=0, le=10,
        description="[m/s^2] separation_speed_m_s: how gently the approach's speed limit falls to it")
    separation_room_m: float = Field(0.0, ge=0, le=50,
        description=("[m] separation_speed_m_s holds from b c + this: room for how far the carrier's own frame may "
                     "put the target from where the passenger separates (relnav: the GNSS frames' bias)"))
    passenger_timeout_s: float = Field(
        1.0, gt=0, le=10,
            description="[s] a passenger status older than this (or a lost liveliness token) stops an approaching carrier")
    state_timeout_s: float = Field(0.5, gt=0, le=10, description="[s] own state older than this stops the carrier")
    p3_margin_m: float = Field(0.5, gt=0, description="[m] the P3 guard keeps the carrier at least b c - margin "
                               "from the target, whatever the passenger does")
    p3_frame: Literal["own", "passenger"] = Field("own",
        description=("[-] the frame the P3 guard runs in: `own` the carrier's own position; `passenger` (relnav: no "
                     "shared frame) its position moved into the passenger's frame, where the targets are, by the bias "
                     "the passenger's status shares while it is usable (p3_bias_*), else its own frame with the margin "
                     "widened by p3_unaligned_margin_m (mission/carrier/frames.py); the carrier's law, the next leg's "
                     "start and its guard all run in that frame"))
    p3_unaligned_margin_m: float = Field(0.0, ge=0, le=20,
        description=("[m] p3_frame `passenger` without a usable bias: the P3 guard runs in the carrier's own frame "
                     "with its margin widened by this (the frames may disagree by metres), and the carrier drives "
                     "this much farther out for the next leg's start (mission/carrier/legs.py)"))
    p3_bias_max_age_s: float = Field(5.0, gt=0, le=600,
        description=("[s] p3_frame `passenger`: a bias heard longer ago is stale (the passenger stops sharing it when "
                     "its marker leaves the camera, a second after it separates, while the carrier still brakes)"))
    p3_bias_max_sigma_m: float = Field(0.5, gt=0, le=20,
        description="[m] p3_frame `passenger`: a bias whose largest standard deviation is above this is not used")
    p3_bias_max_m: float = Field(5.0, gt=0, le=100,
        description=("[m] p3_frame `passenger`: a bias larger than this is implausible, dropped; what a hostile "
                     "passenger can move the guard by"))
    p3_bias_max_step_m: float = Field(0.5, gt=0, le=10,
        description=("[m] p3_frame `passenger`: a sample this far from the guard's bias is a jump, dropped (a run of "
                     "steady samples starts from it)"))
    p3_bias_tau_s: float = Field(1.0, ge=0, le=60,
        description=("[s] p3_frame `passenger`: the guard's bias is the samples smoothed with this time constant "
                     "(0: the newest sample); a sample moves it at most p3_bias_max_step_m (1 - exp(-dt / tau))"))
    p3_bias_settle_s: float = Field(1.0, ge=0, le=60,
        description=("[s] p3_frame `passenger`: the guard enters the passenger's frame once the bias has been usable "
                     "and steady this long"))
    brake_decel_m_s2: float | None = Field(None, gt=0, description="[m/s^2] braking the guard plans with; "
                                           "default safety.carrier_max_accel_m_s2, else 1")
    brake_delay_s: float | None = Field(None, ge=0, le=5, description="[s] the carrier's response delay (command "
                                        "to motion, plus the age of its state) the guard allows for; default 0 for "
                                        "the built-in robot, 0.3 s for a real one (mavlink, ros2)")
    turn_radius_m: float | None = Field(None, ge=0, description="[m] diff-drive/Ackermann: the tightest turn "
                                        "the P3 guard allows for while the carrier stops (its whole stopping path, a turn "
                                        "in progress included, keeps out of b c - margin); default: Ackermann "
                                        "wheelbase_m / tan(max_steer_rad), diff-drive 0 (it turns on the spot)")
    turn_reserve_m: float = Field(0.0, ge=0, description="[m] diff-drive/Ackermann: the radius of its turn away "
                                  "from a target it faces, which the P3 guard keeps in reserve (an Ackermann carrier "
                                  "that cannot reverse, as a PX4 rover in OFFBOARD, drives on while it turns round); "
                                  "below p3_margin_m; 0 off")
    avoid_other_targets: bool = Field(True, description="[-] a mission with several targets: the carrier's CBF "
                                      "filter (safety.filter_carrier) keeps it b c from the targets of the other legs, "
                                      "so that it steers round them instead of its P3 guard braking it at them")
    kinematics: Literal["holonomic", "diff_drive", "ackermann"] = Field("holonomic",
        description=("[-] what the carrier can follow: `holonomic` (any planar velocity), `diff_drive` or `ackermann` "
                     "(tracking law: speed scaled by the heading error, yaw rate to the bearing)"))
    heading_gain: float = Field(2.0, gt=0, description="[1/s] tracking law: yaw rate per heading error")
    max_yaw_rate_rad_s: float = Field(1.0, gt=0, description="[rad/s] tracking law: yaw rate limit")
    min_speed_fraction: float = Field(0.3, ge=0, le=1,
        description=("[-] tracking law, Ackermann: fraction of the speed kept while misaligned (it turns only while "
                     "moving)"))
    wheelbase_m: float = Field(0.3, gt=0,
        description="[m] tracking law, Ackermann: wheelbase (yaw rate <= v tan(max_steer) / wheelbase)")
    max_steer_rad: float = Field(0.5, gt=0, lt=1.5, description="[rad] tracking law, Ackermann: steering angle limit")
    align_on_deck_m: float = Field(0.0, ge=0, le=5, description="[m] largest horizontal shift of the carrier's "
                                   "estimate onto the passenger's while it stands on the deck (before take-off); 0 off")
    speed_ratio_tau_s: float = Field(0.0, ge=0, le=30, description="[s] diff-drive/Ackermann: time constant of the "
                                     "estimate r >= 1 of measured over asked forward speed; the vehicle is asked for v / r "
                                     "(a speed loop that overshoots); 0 off")
    acceleration_tau_s: float = Field(0.0, ge=0, le=5, description="[s] publish the carrier's measured acceleration "
                                      "(its velocity's change, low-passed with this time constant) for the passenger's "
                                      "feed-forward; 0: send none (the passenger predicts it from the carrier law)")
    velocity_bias_tau_s: float = Field(0.0, ge=0, le=60,
        description=("[s] the carrier publishes its velocity plus the low-passed (this time constant) difference "
                     "between its position's rate and its estimator's velocity, so the passenger's feed-forward moves "
                     "as the dock does (a PX4 rover's EKF position ran 0.1-0.3 m/s faster than its velocity); 0 off"))
    velocity_bias_across_tau_s: float = Field(0.0, ge=0, le=60,
        description=("[s] with velocity_bias_tau_s, the difference's part across the carrier's heading is low-passed "
                     "with this time constant instead (a PX4 rover's EKF position drifts sideways while its heading "
                     "holds; the published velocity, along its heading, then ran short across it); 0: "
                     "velocity_bias_tau_s"))
    start_accel_m_s2: float = Field(0.0, ge=0, le=100,
        description=("[m/s^2] the carrier's gentle start: while it is measured slower than 0.15 m/s its command's "
                     "speed grows at most this fast (stiction: it breaks free at a low command, not leaping to a high "
                     "one); 0 off"))
    start_lead_m_s: float = Field(0.0, ge=0, le=100,
        description=("[m/s] once it moves (measured at 0.15 m/s or more), its command's speed is at most its measured "
                     "speed plus this: a rover that crawls while its command runs on winds up its speed loop and leaps "
                     "(mission.carrier.start); 0 off"))
    min_moving_speed_m_s: float = Field(0.0, ge=0, le=100,
        description=("[m/s] diff-drive/Ackermann: while the law asks at least this planar speed, the forward speed "
                     "asked is at least this too (the gentle start, the lead and the tracking law's slowing in a turn "
                     "never ask less); below it, the law's own speed: no crawl that a speed loop whose estimate errs by "
                     "about this much cannot hold (mission.carrier.start); and before a leg after the first it turns "
                     "at this speed to face the leg's target, then stands (mission.carrier.legs); 0 off"))
    floor_from_m_s: float = Field(0.0, ge=0, le=100,
        description=("[m/s] diff-drive/Ackermann: min_moving_speed_m_s's floor sets in once the carrier moves (forward or "
                     "across its heading) at this speed, not at 0.15 m/s: a SIH rover crawling at 0.15-0.3 m/s off a "
                     "stand was asked the floor's ramp to 0.8 m/s, did not follow for 0.5 s, then leapt to 1.1-1.5 "
                     "m/s under the riding passenger (start_lead_m_s holds it back below); 0: 0.15 m/s"))
    start_motion_tau_s: float = Field(0.0, ge=0, le=60,
        description=("[s] the gentle start, the lead and the floor judge whether the carrier moves (and, "
                     "diff-drive/Ackermann, how fast across its heading) by its velocity made consistent with its "
                     "position, the difference low-passed with this time constant (mission.core.consistent_velocity), "
                     "not by its estimator's velocity alone: a PX4 rover standing still was estimated at 0.2-0.3 m/s "
                     "and was asked the floor's ramp instead of the gentle start; 0 off"))
    speed_loop_correction: float = Field(0.0, ge=0, le=1,
        description=("[-] diff-drive/Ackermann behind an autopilot's own speed loop (PX4's rover): the forward speed "
                     "asked is raised by this fraction of how much faster that loop measures the carrier (its EKF "
                     "velocity's size signed by the forward part) than its velocity made consistent with its position "
                     "(start_motion_tau_s) says it moves: a SIH rover standing while its EKF read -0.3 m/s broke free "
                     "early, stalled as the reading flipped to +0.3, and leapt; RO_SPEED_P / (RO_SPEED_P + "
                     "1 / RO_MAX_THR_SPEED) cancels the error in PX4's throttle (mission.carrier.tracking); 0 off"))
    fix_smoothing_tau_s: float = Field(0.0, ge=0, le=60,
        description=("[s] where the own state is a GNSS fix with the robot's inertial velocity beside it (the "
                     "simulators' world errors), steer and guard on the fix low-passed with this time constant and "
                     "moved on by that velocity, as a rover's EKF fuses GNSS with its wheels and IMU (the bias stays, "
                     "the fix-to-fix noise goes); what it publishes is still the fix; 0: steer on the fix"))
    recovery_speed_m_s: float = Field(0.0, ge=0, le=100,
        description=("[m/s] while the passenger comes home (returns, holds off, approaches, docks) the carrier drives "
                     "its steady recovery course at this speed, after the legs of recovery_course; 0: it stops and waits "
                     "(at most max_speed_m_s)"))
    recovery_heading_deg: float | None = Field(None, ge=-360, le=360,
        description=("[deg] NED heading (0 north, 90 east) of the steady recovery course; default: away from the target "
                     "(the bearing from the target to where the carrier is when the recovery begins), turned as little as "
                     "clears the other targets' keep-outs (at most 90 deg)"))
    recovery_course: list[list[float]] = Field([], max_length=MAX_COURSE_LEGS,
        description=("[deg, m/s, s] scripted legs `[heading_deg, speed_m_s, duration_s]` the carrier drives in order "
                     "from the start of the recovery, before the steady course (e.g. a 90 deg turn mid-approach); "
                     "heading NED in -360..360, speed 0..max_speed_m_s, duration in (0, 3600]"))
    start_yaw_rad: float | None = Field(None,
        description="[rad] sim backend: initial heading (default: towards the target)")
    mavlink: CarrierMavlinkSection = Field(CarrierMavlinkSection(),
        description="[-] table: the PX4 vehicle of the `mavlink` backend")
    ros2: CarrierRos2Section = Field(CarrierRos2Section(),
        description="[-] table: the ROS 2 robot of the `ros2` backend")

    @model_validator(mode="after")
    def _vectors(self) -> "CarrierSection":
        for name, v in (("mavlink.offset_ned_m", self.mavlink.offset_ned_m), ("ros2.offset_ned_m", self.ros2.offset_ned_m)):
            if len(v) != 3:
                raise ConfigError(f"carrier.{name}", v, "must have 3 components")
        if self.mavlink.shared_origin is not None and len(self.mavlink.shared_origin) != 3:
            raise ConfigError("carrier.mavlink.shared_origin", self.mavlink.shared_origin, "must be [lat, lon, alt]")
        if self.turn_reserve_m >= self.p3_margin_m:
            raise ConfigError("carrier.turn_reserve_m", self.turn_reserve_m,
                              f"must be below carrier.p3_margin_m = {self.p3_margin_m:g} (the carrier could not "
                              "reach b c, where the passenger separates, and keep room to turn away)")
        if self.recovery_speed_m_s > self.max_speed_m_s:
            raise ConfigError("carrier.recovery_speed_m_s", self.recovery_speed_m_s,
                              f"above carrier.max_speed_m_s = {self.max_speed_m_s:g}")
        for i, leg in enumerate(self.recovery_course):
            name = f"carrier.recovery_course[{i}]"
            if len(leg) != 3:
                raise ConfigError(name, leg, "must be [heading_deg, speed_m_s, duration_s]")
            heading, speed, duration = leg
            if not -360.0 <= heading <= 360.0:
                raise ConfigError(name, leg, "heading_deg must be in -360..360")
            if not 0.0 <= speed <= self.max_speed_m_s:
                raise ConfigError(name, leg, f"speed_m_s must be in 0..carrier.max_speed_m_s = {self.max_speed_m_s:g}")
            if not 0.0 < duration <= 3600.0:
                raise ConfigError(name, leg, "duration_s must be in (0, 3600]")
        return self
