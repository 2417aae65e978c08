"""Typed, validated configuration from TOML (pydantic models; errors name the field).

One file describes a whole marsupial pair: the law, the scenario geometry, the safety filter,
the simulator, the mission controller, the MAVLink and Zenoh endpoints and the carrier
simulator. Every section has safe defaults, so a file only states what differs. Layering: file,
then command-line overrides (:func:`with_overrides`).

Frames: ``scenario`` vectors are in the local frame of the flight, PX4's local NED [m] (z down)
for missions; the simulator is frame-agnostic (``scenario.frame`` only affects plots).

Everything is checked at load and a bad value raises :class:`ConfigError` naming the field (the
CLI exits 2): the file must be UTF-8 TOML; numbers are strict (a string or a boolean is never a
number, an integer field takes no fraction); every margin, timeout, rate, speed, gain and
string length has bounds (a 1e300 timeout would switch a failsafe off, a 0.001 Hz loop would not
hear SIGTERM for 1000 s); URLs, ports and Zenoh endpoints and key expressions are parsed; and the
geometry is checked across fields (:meth:`Config._cross_fields`): altitude band not empty, dock
point above the carrier and inside the band, target inside the band and above ground, starts and
target outside every obstacle, departure margin well inside b c, carrier rate fast enough for
the carrier timeout; with several targets, every leg can start under the paper's Assumption 1
(:mod:`mission.config.legs`); with a ``[team]``, one passenger per slot and per target, every slot
a dock point as above, and every passenger's own configuration valid (:mod:`mission.config.team`).
"""
from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import numpy as np
from pydantic import Field, ValidationError, field_validator, model_validator

from mission.config.carrier import CarrierMavlinkSection, CarrierRos2Section, CarrierSection
from mission.config.legs import check_legs, first_target_named
from mission.config.recovery import RecoverySection, check_recovery
from mission.config.relnav import RelnavSection, WorldSection
from mission.config.safety import SafetySection
from mission.config.scenario import ObstacleSection, ScenarioSection
from mission.config.team import (TeamSection, as_team_error, check_queue, check_slot_markers, check_team, dock_points,
                                 passenger_data)
from mission.config.urls import DEFAULT_URL
from mission.config.vision import VisionSection, check_vision
from mission.config.fields import (
    COORD_LIMIT_M, MAX_PATH_CHARS, MAX_URL_CHARS, Coord, FloatPair, Path_, Section, check_key_expr, check_mavlink_url,
    check_port, check_zenoh_endpoint, printable,
)
from mission.errors import ConfigError

if TYPE_CHECKING:  # the schema imports no law: the converters below import it when called
    from mission.core.law import LawParams

__all__ = [  # the sections and field checks in config_carrier / config_fields are importable from here too
    "COORD_LIMIT_M", "MAX_PATH_CHARS", "MAX_URL_CHARS", "CarrierMavlinkSection", "CarrierRos2Section",
    "CarrierSection", "Config", "Coord", "FloatPair", "LawSection", "MavlinkSection", "MissionSection",
    "MonteCarloSection", "ObstacleSection", "Path_", "SafetySection", "ScenarioSection", "Section", "SimSection",
    "ZenohSection", "check_key_expr", "check_mavlink_url", "check_port", "check_zenoh_endpoint", "from_dict",
    "load_config", "with_overrides",
]


class LawSection(Section):
    """Gains of the paper's law (paper values by default)."""

    k_c: float = Field(0.5, gt=0, le=100,
        description="[1/s] carrier gain: u_c = k_c e_tc while the passenger is docked (paper eq. 4)")
    k_p: float = Field(1.0, gt=0, le=100,
        description="[1/(m^3 s)] passenger gain: P = k_p (a - L)(a + d)(a - L/b + c) is in 1/s (paper eq. 6)")
    b: float = Field(8.0, gt=1, le=1000,
        description="[-] shape of the potential, > 1; separation when the carrier is within b c of the target")
    c: float = Field(1.0, gt=0, le=1000,
        description="[m] shape of the potential; b c is the separation distance (8 m with the paper's values)")
    d: float = Field(1.0, gt=0, le=1000, description="[m] shape of the potential (paper eq. 6)")
    departure_margin_m: float = Field(
        1e-3, gt=0, le=0.5,
            description="[m] separation fires at |e_tc| = b c - this (the paper's T+), in flights and simulations")

    def params(self) -> LawParams:
        from mission.core.law import LawParams

        return LawParams(k_c=self.k_c, k_p=self.k_p, b=self.b, c=self.c, d=self.d)


class SimSection(Section):
    """Numeric closed loop: a fixed step with the command held over it (a digital controller);
    and the lockstep runs' wait for a slow carrier."""

    dt_s: float = Field(1e-3, gt=0, le=0.1,
        description="[s] step of the simulated digital controller (command held over it)")
    duration_s: float = Field(30.0, gt=0, le=100_000, description="[s] simulated time from the start of riding (t = 0)")
    p1_tolerance_m: float = Field(1e-6, gt=0, le=10,
        description="[m] |e_pc| counted as 'on the carrier' before separation (P1)")
    p2_tolerance_m: float = Field(0.1, gt=0, le=10,
        description="[m] final |e_pt| counted as 'at the target' (P2); a mission config uses mission.arrival_radius_m")
    lockstep_carrier_wait_wall_s: float = Field(20.0, ge=2, le=600,
        description="[s, wall] a lockstep run (marsupial run --lockstep): how long the controller waits for a step of a "
                    "carrier whose liveliness token is present (slow, not gone: a loaded machine, a stopped process) "
                    "before it goes on without it, and the run is no longer lockstep (docs/lockstep.md); the vehicle "
                    "is told meanwhile that the controller still works on the step")


class MonteCarloSection(Section):
    """Random scenarios satisfying the assumptions (for --monte-carlo)."""

    distance_m: FloatPair = Field((12.0, 60.0),
        description="[m] range of the random targets' horizontal distance from the carrier (raised above b c)")
    height_m: FloatPair = Field((0.0, 6.0),
        description="[m] range of the random targets' height above the carrier's plane (3D; clipped to 0.95 b c)")

    @model_validator(mode="after")
    def _ranges(self) -> "MonteCarloSection":
        for name in ("distance_m", "height_m"):
            lo, hi = getattr(self, name)
            if not (0 <= lo <= hi <= COORD_LIMIT_M):
                raise ConfigError(f"monte_carlo.{name}", [lo, hi], f"must be 0 <= low <= high <= {COORD_LIMIT_M:g}")
        return self


class MissionSection(Section):
    """The offboard controller (``marsupial run``)."""

    rate_hz: float = Field(50.0, ge=10, le=1000,
        description="[Hz] controller tick and setpoint rate (PX4 needs > 2 Hz in OFFBOARD)")
    dock_offset_ned_m: list[Annotated[float, Field(ge=-100, le=100)]] = Field(
        [0.0, 0.0, -1.5],
            description=("[m] NED offset of the dock point from the carrier's reported position (the passenger rides "
                         "there; -1.5 = 1.5 m above)"))
    dock_tolerance_m: float = Field(0.5, gt=0, le=5,
        description=("[m] how far from the dock point the vehicle may be at start-up (horizontally) and while riding "
                     "(P1)"))
    track_gain: float = Field(0.0, ge=0, le=50,
        description="[1/s] pull of the vehicle onto the reference: u = u_ref + gain (x_ref - x_p)")
    join_speed_m_s: float = Field(1.0, gt=0, le=20,
        description="[m/s] speed of the reference from take-over to the dock point (JOIN)")
    arrival_radius_m: float = Field(0.5, gt=0, le=50,
        description="[m] distance to the target that counts as arrived (P2)")
    arrival_dwell_s: float = Field(2.0, ge=0, le=600,
        description="[s] time the vehicle must stay within the arrival radius")
    setpoint: Literal["velocity", "full"] = Field(
        "full", description="[-] velocity-only setpoints (type_mask 3527), or position + velocity + acceleration "
        "(type_mask 3072: PX4 closes position itself); see mission/core/tracking.py")
    position_lead: float = Field(2.6, ge=0, le=20, description="[-] full setpoints: the position sent is x_ref + lead (x_ref - x_p), "
                                 "extra position feedback through PX4's own position loop (dimensionless)")
    integral_gain: float = Field(1.0, ge=0, le=20, description="[1/s^2 or 1/s] integral action on the position error: [1/s^2] into the "
                                 "acceleration feed-forward (full), [1/s] into the velocity (velocity)")
    integral_limit: float = Field(2.0, gt=0, le=20,
        description="[m/s^2 or m/s] clamp of the integral term: [m/s^2] (full) or [m/s] (velocity)")
    drag_ff_per_s: float = Field(1.0, ge=0, le=10, description="[1/s] feed-forward of the vehicle's velocity deficit: "
                                 "acceleration per m/s of reference velocity (full setpoints)")
    integral_window_m: float = Field(0.5, gt=0, le=10, description="[m] the integral integrates only while the vehicle is "
                                     "this close to the reference (anti-windup)")
    velocity_bias_tau_s: float = Field(0.0, ge=0, le=60, description="[s] the vehicle's velocity as the mission uses it "
                                       "is corrected by the low-passed (this time constant) difference between its position's "
                                       "rate and its estimator's velocity (PX4's EKF on SIH: 0.3-0.5 m/s apart for seconds); 0 off")
    near_deck_velocity_bias_tau_s: float | None = Field(None, gt=0, le=60, description="[s] velocity_bias_tau_s in "
        "the phases over the deck (JOIN, RIDING, TRANSIT, HOLDOFF, APPROACH, GO_AROUND, DOCKED, HOME; None: "
        "velocity_bias_tau_s; needs it > 0): a shorter one follows the position's rate closer where the speed relative "
        "to the deck decides the contact and the ride (docs/relnav.md)")
    damping_per_s: float = Field(0.0, ge=0, le=20, description="[1/s] full setpoints: velocity damping in the acceleration "
                                 "feed-forward, -k (v_p - u_ref): damps the ringing of PX4's position loop stiffened by the lead; 0 off")
    near_deck_damping_per_s: float | None = Field(None, ge=0, le=20, description="[1/s] damping_per_s in HOLDOFF and "
        "APPROACH, over the deck (None: damping_per_s): there the loop closes on the marker, 50-150 ms late, and rang at "
        "about 0.6 Hz, +-0.2 m/s sideways against the deck under a steady command (docs/relnav.md, \"Damping the last "
        "decimetre\"). It steps the acceleration sent by the change times the velocity error as those phases begin and end")
    bias_compensation_s: float = Field(0.0, ge=0, le=10, description="[s] full setpoints: the position sent also "
                                       "carries this times the estimator's velocity bias (its velocity less its position's "
                                       "rate, low-passed: needs velocity_bias_tau_s > 0), so PX4's velocity setpoint "
                                       "carries the bias and it no longer moves the position PX4 holds; 1/MPC_XY_P "
                                       "(1.05 s) cancels it; 0 off")
    carrier_accel_horizon_s: float = Field(0.0, ge=0, le=5, description="[s] riding, the carrier's acceleration fed forward (unless it sends one) is its law's "
        "change of velocity over this time (at most its limit), not over one carrier step: an estimated velocity's noise is then no bang-bang; 0: one step")
    accel_lead_s: float = Field(0.0, ge=0, le=2, description="[s] full setpoints: the reference's acceleration is sent "
                                "ahead of the vehicle's own acceleration lag, this time constant (SIH quadrotor: 0.28 s), "
                                "through a lead-lag down to accel_lead_filter_s; 0 off")
    accel_lead_filter_s: float = Field(0.1, gt=0, le=2, description="[s] the lag the vehicle's acceleration is left with "
                                       "(see accel_lead_s)")
    reference_slow_lag_m: float | None = Field(
        0.3, gt=0, le=50, description="[m] after separation the reference slows down when the vehicle lags it by more "
        "than this, and waits at reference_stop_lag_m (None: never)")
    reference_stop_lag_m: float | None = Field(1.0, gt=0, le=50, description="[m] see reference_slow_lag_m")
    join_settle_m: float | None = Field(
        0.15, gt=0, le=5, description="[m] JOIN ends (the carrier starts) once the vehicle is this close to the dock point "
        "(None: dock_tolerance_m) ...")
    join_settle_s: float = Field(0.5, ge=0, le=60, description="[s] ... for this long")
    arrival_max_speed_m_s: float | None = Field(
        0.3, gt=0, le=20, description="[m/s] arrival also needs the vehicle this slow (None: any speed), so Hold is "
        "not handed a vehicle still moving")
    telemetry_rate_hz: float | None = Field(
        50.0, gt=0, le=1000, description="[Hz] LOCAL_POSITION_NED rate asked of the vehicle (MAV_CMD_SET_MESSAGE_INTERVAL); "
        "None: leave the vehicle's default")
    unused_streams: Literal["keep", "stop"] = Field(
        "keep", description="[-] `stop`: once the preflight checks passed, ask the vehicle to stop the onboard-profile "
        "streams the mission never reads (SET_MESSAGE_INTERVAL -1 each; PX4 honours it on the link it came on), so "
        "less telemetry is sent and parsed; `keep`: leave them streaming (the tlog then has them all)")
    final_action: Literal["hold", "land", "return"] = Field("hold",
        description=("[-] after arrival: `hold` (PX4 Hold, armed in the air), `land`, or `return` to the carrier and "
                     "dock on it ([recovery])"))
    ride: Literal["hover", "deck"] = Field(
        "hover", description=("[-] how the passenger is carried: `hover` flies in formation on the dock point; `deck` "
                              "sits on the deck (the dock point is then the deck: mission.dock_offset_ned_m), disarmed, "
                              "arms mission.arm_lead_s before the separation and takes off from the moving deck; after "
                              "docking it lands on the deck and disarms (docs/deck-riding.md)"))
    arm_lead_s: float = Field(
        4.0, ge=1, le=8, description=("[s] with ride = `deck`: the passenger streams its setpoints, arms and enters "
                                      "OFFBOARD this long before the separation it predicts from the carrier's closing "
                                      "speed (PX4 disarms a vehicle that has not taken off COM_DISARM_PRFLT, 10 s, after "
                                      "arming)"))
    deck_clear_height_m: float = Field(
        1.0, gt=0, le=10, description=("[m] with ride = `deck`: height above the deck below which the deck's keep-out "
                                       "acts in the safety filter (the passenger may not move out sideways from the deck "
                                       "faster than it climbs: see deck_clear_slope)"))
    deck_clear_slope: float = Field(
        3.0, gt=0, le=20, description=("[-] with ride = `deck`: the keep-out round the deck is everything low beside it: "
                                       "below deck_clear_height_m, the passenger stays within deck_keep_out_radius_m + "
                                       "this times its height above the deck, horizontally from the dock point "
                                       "(a funnel; must exceed the glide path's horizontal per vertical)"))
    deck_keep_out_radius_m: float = Field(
        0.15, gt=0, le=5, description=("[m] with ride = `deck`: the funnel's radius at the deck (see deck_clear_slope): "
                                       "how far the passenger may slide across the deck before it has climbed"))
    deck_press_floor_m: float = Field(
        0.5, gt=0, le=5, description=("[m] with ride = `deck`: after a contact the landing presses the reference 0.1 m "
                                      "below the height the passenger reports (PX4 flies its estimate, whose height errs "
                                      "by decimetres), only while it reports itself over the deck "
                                      "(recovery.deck_radius_m), and never deeper than this below the deck's plane: a "
                                      "few sigma of PX4's vertical estimate error (SITL: 0.3 m); safety.z_max_m, when "
                                      "shallower, bounds it further"))
    leg_start_margin_m: float = Field(2.0, gt=0, le=1000,
        description=("[m] with several targets: a leg starts (the passenger rides under the law again) once the "
                     "carrier is b c + this from the leg's target (the paper's Assumption 1); nearer, the carrier "
                     "first drives out (TRANSIT)"))
    at_target_s: float = Field(0.0, ge=0, le=86400,
        description="[s] with final_action = `return`: time spent at the target (the task) before coming home")
    carrier_timeout_s: float = Field(0.5, gt=0, le=10,
        description=("[s] before separation, a carrier state older than this (since the carrier measured it, with the "
                     "clock offset's bound) is not fresh: the passenger rides the dock point predicted with its age, "
                     "but does not separate on it; none fresh for carrier_lost_s: abort (carrier_lost)"))
    carrier_lost_s: float = Field(1.5, gt=0, le=60,
        description=("[s] before separation, no fresh carrier state (see carrier_timeout_s) for this long: abort "
                     "(carrier_lost), Hold. Covers a stalled carrier process or link (a 1 s SIGSTOP); a carrier whose "
                     "liveliness token is gone aborts at once"))
    dock_rejoin_speed_m_s: float = Field(1.0, gt=0, le=5,
        description=("[m/s] before separation, riding a carrier state that is not fresh (see carrier_timeout_s) and "
                     "back on a fresh one: the reference chases the dock point at most this fast relative to it, and "
                     "its velocity changes at most at safety.passenger_max_accel_m_s2, so the dock point a fresh state "
                     "puts elsewhere than the prediction (a carrier that braked in the gap) is taken back smoothly"))
    carrier_settle_s: float = Field(
        2.0, ge=0, le=30, description="[s] a carrier state the feed has just re-accepted (a newly bound carrier, a "
        "resync after a jump) must stay within the carrier's own speed and acceleration limits this long, and its "
        "source must not be contested, before the passenger rides on it or separates on it; until then it holds on "
        "the dock point it had (mission/bus/gate.py)")
    heartbeat_timeout_s: float = Field(3.0, gt=0, le=30,
        description="[s] vehicle lost when HEARTBEAT and telemetry are silent this long (MAVSDK: 3 s)")
    prestream_s: float = Field(1.0, ge=0.2, le=10,
        description=("[s] zero-velocity setpoints streamed before asking for OFFBOARD (PX4 refuses OFFBOARD without a "
                     "stream)"))
    command_retries: int = Field(3, ge=1, le=10,
        description="[-] tries of each vehicle command (arm, OFFBOARD, Hold, Land) before giving up")
    max_duration_s: float = Field(300.0, gt=0, le=86400, description="[s] mission timeout: Hold after this long")
    connect_timeout_s: float = Field(20.0, gt=0, le=600,
        description="[s] how long `run` waits for the vehicle and the carrier before giving up (it counts down)")
    log_dir: Path_ = Field("logs", description="[-] directory of flight logs (`<log_dir>/<time>-<pair>/`)")
    feeds: list[Annotated[str, Field(pattern=r"^[a-z0-9_\-]+$", max_length=64)]] = Field([], max_length=16,
        description=("[-] measurement feeds to open, by name: `run` opens each registered in the entry-point group "
                     "`marsupial.feeds`, `simulate` gives the world its sensor of the same name (`marsupial.sensors`)"))

    _log_dir_printable = field_validator("log_dir")(printable)

    @model_validator(mode="after")
    def _near_deck_bias(self) -> "MissionSection":
        if self.near_deck_velocity_bias_tau_s is not None and self.velocity_bias_tau_s <= 0:
            raise ConfigError("mission.near_deck_velocity_bias_tau_s", self.near_deck_velocity_bias_tau_s,
                              "needs mission.velocity_bias_tau_s > 0: it changes that filter's time constant near the deck")
        return self


class MavlinkSection(Section):
    url: str = Field(DEFAULT_URL, max_length=MAX_URL_CHARS,
        description=("[-] vehicle endpoint: udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT or a serial device "
                     "/dev/ttyACM0:921600"))
    target_system: int | None = Field(None, ge=1, le=255,
        description="[-] MAVLink system id of the vehicle (default: the first that sends HEARTBEAT)")
    target_component: int = Field(1, ge=0, le=255, description="[-] the autopilot's component id (0: any)")
    source_system: int = Field(1, ge=1, le=255, description="[-] our MAVLink system id")
    source_component: int = Field(191, ge=1, le=255, description="[-] our MAVLink component id (191: onboard computer)")
    signing_key_file: Path_ | None = Field(None,
        description="[-] MAVLink 2 signing key file (64 hex digits or 32 bytes); everything sent is signed")

    _url_ok = field_validator("url")(check_mavlink_url)
    _key_file_printable = field_validator("signing_key_file")(lambda v: v if v is None else printable(v))


class ZenohSection(Section):
    """Zenoh session: peer on loopback with multicast scouting off by default."""

    mode: Literal["peer", "client", "router"] = Field("peer",
        description="[-] Zenoh session mode: `peer`, `client` or `router`")
    listen: list[Annotated[str, Field(max_length=MAX_URL_CHARS)]] = Field([], max_length=16,
        description="[-] Zenoh endpoints to listen on, e.g. `tcp/127.0.0.1:7450`")
    connect: list[Annotated[str, Field(max_length=MAX_URL_CHARS)]] = Field([], max_length=16,
        description="[-] Zenoh endpoints to connect to, e.g. `tcp/127.0.0.1:7447` (a router)")
    multicast_scouting: bool = Field(False,
        description="[-] find peers by UDP multicast (off: loopback only, explicit endpoints)")
    config_file: Path_ | None = Field(None,
        description="[-] a Zenoh JSON5 config file as the base (see configs/zenoh/); listen/connect still override")
    pair: str = Field("pair0", pattern=r"^[A-Za-z0-9_\-]+$", max_length=64,
                      description="[-] pair name: the key namespace `marsupial/<pair>/...` (letters, digits, _ and -)")
    encoding: Literal["json", "cdr"] = Field("json",
        description="[-] carrier state encoding: `json` or `cdr` (ROS 2 nav_msgs/Odometry)")
    rendezvous: str | None = Field(
        "tcp/127.0.0.1:7448",
        description=("[-] peers with no endpoints meet on this loopback endpoint (the first process listens); none: "
            "ephemeral listener only"),
    )
    carrier_key: str | None = Field(
        None, max_length=MAX_URL_CHARS,
        description=("[-] override of the carrier state key, e.g. `robot1/odom` (zenoh-bridge-ros2dds) or "
            "`0/odom/nav_msgs::msg::dds_::Odometry_/*` (rmw_zenoh)"))

    @field_validator("listen", "connect")
    @classmethod
    def _endpoints(cls, value: list[str], info: Any) -> list[str]:
        for endpoint in value:
            check_zenoh_endpoint(endpoint, listen=info.field_name == "listen")
        return value

    @field_validator("rendezvous")
    @classmethod
    def _rendezvous(cls, value: str | None) -> str | None:
        return None if value is None else check_zenoh_endpoint(value, listen=False)

    @field_validator("carrier_key")
    @classmethod
    def _key(cls, value: str | None) -> str | None:
        return None if value is None else check_key_expr(value)

    signing_key_file: Path_ | None = Field(
        None, description="[-] 32-byte key (64 hex digits or raw) the pair signs its bus samples with (carrier state, "
        "passenger status, lockstep clock, ROS 2 commands; mission/bus/signing.py); unsigned or badly signed samples are "
        "then dropped and counted. Both robots of a pair need the same file, and either can sign as the other: prefer "
        "private_key_file and peer_public_key_file. None: unsigned (the mTLS + ACL router is the fleet's answer)")

    private_key_file: Path_ | None = Field(
        None, description="[-] this robot's own Ed25519 private key (PEM, e.g. `openssl genpkey -algorithm ed25519`, or "
        "its 32-byte seed as 64 hex digits or raw): it signs every sample this robot puts on the pair's bus. With "
        "peer_public_key_file: one key per robot, and signing_key_file then only signs a carrier's own ROS 2 robot link")
    peer_public_key_file: Path_ | None = Field(
        None, description="[-] the other robot's Ed25519 public key (PEM, or 32 bytes as 64 hex digits or raw): the only "
        "key its samples verify with; unsigned or badly signed samples are dropped and counted")

    public_keys_dir: Path_ | None = Field(None, description="[-] a team's one key per robot: a directory of every "
        "robot's Ed25519 public key (as peer_public_key_file's), `carrier.pub` and `<name>.pub` per team.passengers; each "
        "robot signs with its own private_key_file, and a sample verifies only with the key of the robot it names")

    _config_file_printable = field_validator("config_file")(lambda v: v if v is None else printable(v))
    _signing_key_printable = field_validator("signing_key_file")(lambda v: v if v is None else printable(v))
    _robot_keys_printable = field_validator("private_key_file", "peer_public_key_file", "public_keys_dir")(
        lambda v: v if v is None else printable(v))

    @model_validator(mode="after")
    def _both_robot_keys(self) -> "ZenohSection":
        if self.public_keys_dir:  # each robot's own private key comes with its process (--zenoh-private-key)
            if self.peer_public_key_file:
                raise ConfigError("zenoh.peer_public_key_file", self.peer_public_key_file, "a team's robots' keys are "
                                  "in zenoh.public_keys_dir: leave out the single peer's")
        elif bool(self.private_key_file) != bool(self.peer_public_key_file):
            missing = "peer_public_key_file" if self.private_key_file else "private_key_file"
            raise ConfigError(f"zenoh.{missing}", None, "one key per robot needs both zenoh.private_key_file and "
                              "zenoh.peer_public_key_file (a team's: zenoh.public_keys_dir)")
        return self

class Config(Section):
    law: LawSection = LawSection()
    scenario: ScenarioSection = ScenarioSection()
    safety: SafetySection = SafetySection()
    sim: SimSection = SimSection()
    monte_carlo: MonteCarloSection = MonteCarloSection()
    mission: MissionSection = MissionSection()
    mavlink: MavlinkSection = MavlinkSection()
    zenoh: ZenohSection = ZenohSection()
    carrier: CarrierSection = CarrierSection()
    recovery: RecoverySection = RecoverySection()
    vision: VisionSection = VisionSection()
    relnav: RelnavSection = RelnavSection()
    world: WorldSection = WorldSection()
    team: TeamSection = TeamSection()

    @model_validator(mode="after")
    def _assumptions(self) -> "Config":
        s = self.scenario
        from mission.core.law import check_assumptions  # the geometry the law needs, checked at load

        check_assumptions(
            np.array(s.carrier_start),
            np.array(s.target),
            self.law.params(),
            planar_carrier=s.planar_carrier and s.dim == 3,
            eta=s.eta,
            passenger_start=None if s.passenger_start is None else np.array(s.passenger_start),
        )
        if not self.carrier.p3_margin_m > self.law.departure_margin_m:
            raise ConfigError("carrier.p3_margin_m", self.carrier.p3_margin_m,
                              "must exceed law.departure_margin_m, or the carrier never reaches the separation distance")
        if self.carrier.p3_margin_m >= self.law.params().separation_distance_m:
            raise ConfigError("carrier.p3_margin_m", self.carrier.p3_margin_m, "must be < b c")
        if self.carrier.p3_margin_m + self.carrier.p3_unaligned_margin_m >= self.law.params().separation_distance_m:
            raise ConfigError("carrier.p3_unaligned_margin_m", self.carrier.p3_unaligned_margin_m,
                              "must be < b c - carrier.p3_margin_m (the guard's radius in the carrier's own frame)")
        if len(self.mission.dock_offset_ned_m) != 3:
            raise ConfigError("mission.dock_offset_ned_m", self.mission.dock_offset_ned_m, "must have 3 components")
        self._cross_fields()
        if self.team.given:
            if self.mission.final_action == "return":  # after the slots' own checks: their queue points
                check_queue(self.team, self.safety.passenger_separation_m + self.safety.margin_m, self.recovery,
                            self.safety.vertical_ratio)
            self._team_flies()
        return self

    def _team_flies(self) -> None:
        """Each passenger of the team flies the single-passenger configuration derived for it
        (:func:`mission.config.team.passenger_data`): refused, naming the team file's field, if that one is."""
        data = self.model_dump(exclude_unset=True)
        for i in range(len(self.team.passengers)):
            try:
                from_dict(passenger_data(data, self.team, self.scenario.legs(), i))
            except ConfigError as exc:
                raise as_team_error(exc, self.team, i, self.scenario.target_field()) from None

    def _cross_fields(self) -> None:
        """Checks that need several fields (raise ConfigError naming the field to change)."""
        s, sf, m = self.scenario, self.safety, self.mission
        bc = self.law.params().separation_distance_m
        team = self.team if self.team.given else None  # one passenger per slot and target
        if team is not None:
            check_team(team, n_targets=len(s.legs()), target_field=s.target_field(), contact_radius_m=self.recovery.contact_radius_m,
                       stated={f"{sec}.{key}": getattr(getattr(self, sec), key) for sec in ("mission", "mavlink", "vision")
                               for key in getattr(self, sec).model_fields_set},
                       carrier_system_id=self.carrier.mavlink.target_system if self.carrier.backend == "mavlink" else None)
            if "marker" in m.feeds:  # each passenger's detector must see its own slot's marker only
                check_slot_markers(team, self.vision.tag_id, self.vision.small_tag_id, self.vision.layout == "bundle")
        docks, leg_docks = dock_points(team, m.dock_offset_ned_m, len(s.legs()))  # (field, offset), each leg's offset
        if not self.law.departure_margin_m >= 1e-6:
            raise ConfigError("law.departure_margin_m", self.law.departure_margin_m,
                              "must be >= 1e-6 m (a smaller departure drowns in float rounding: the passenger stays)")
        if not self.law.departure_margin_m < bc / 10:
            raise ConfigError("law.departure_margin_m", self.law.departure_margin_m,
                              f"must be < b*c/10 = {bc / 10:g} m (at >= b*c the passenger never separates)")
        if m.bias_compensation_s > 0 and not m.velocity_bias_tau_s > 0:
            raise ConfigError("mission.bias_compensation_s", m.bias_compensation_s,
                              "needs mission.velocity_bias_tau_s > 0 (the bias it compensates is measured there)")
        if sf.z_min_m is not None and sf.z_max_m is not None and not sf.z_min_m < sf.z_max_m:
            raise ConfigError("safety.z_min_m", sf.z_min_m, f"empty altitude band: must be < safety.z_max_m = {sf.z_max_m:g}")
        for i, ob in enumerate(s.obstacles):
            for name in ("carrier_start", "target", "passenger_start"):
                point = getattr(s, name)
                if point is not None and math.dist(point, ob.center) <= ob.radius:
                    raise ConfigError(f"scenario.{name}", point, f"inside scenario.obstacles[{i}] "
                                      f"(center {ob.center}, radius {ob.radius:g} m)")
        # several targets: every leg can start under Assumption 1 (mission/config/legs.py)
        check_legs(s, final_action=m.final_action, bc_m=bc, leg_start_margin_m=m.leg_start_margin_m,
                   dock_offsets_ned_m=leg_docks, p3_margin_m=self.carrier.p3_margin_m,
                   safety_margin_m=sf.margin_m)
        check_recovery(self.recovery, self.carrier, carrier_max_speed_m_s=sf.carrier_max_speed_m_s,  # it can finish
                       passenger_max_speed_m_s=sf.passenger_max_speed_m_s, final_action=m.final_action)
        check_vision(self.vision, self.recovery.decision_height_m, m.dock_offset_ned_m)  # the marker in view at the gate
        if s.dim != 3 or s.frame != "local_ned":
            return
        # local NED, z down: the carrier drives on the ground at carrier_start's z
        ground = s.carrier_start[2]
        for name, offset in docks:
            if not offset[2] < 0:
                raise ConfigError(name, offset, "the dock point must be above the carrier (down component < 0): it is "
                                  "underground")
        if not s.target[2] <= ground:
            raise ConfigError("scenario.target", s.target, f"below the ground (z {s.target[2]:g} > carrier z {ground:g}, NED)")
        for name, value, z in [(name, offset, ground + offset[2]) for name, offset in docks] + [
                ("scenario.target", s.target, s.target[2])]:
            if sf.z_max_m is not None and z > sf.z_max_m:
                raise ConfigError(name, value, f"below the altitude floor safety.z_max_m = {sf.z_max_m:g} (z {z:g}, NED)")
            if sf.z_min_m is not None and z < sf.z_min_m:
                raise ConfigError(name, value, f"above the ceiling safety.z_min_m = {sf.z_min_m:g} (z {z:g}, NED)")
        if m.ride == "deck":
            for name, offset in docks:
                self._deck_fields(name, offset, ground + offset[2])
        for j, later in enumerate(s.legs()[1:], start=1):
            if not later[2] <= ground:
                raise ConfigError(f"scenario.targets[{j}]", later, f"below the ground (z {later[2]:g} > carrier z {ground:g}, NED)")
            if sf.z_max_m is not None and later[2] > sf.z_max_m:
                raise ConfigError(f"scenario.targets[{j}]", later, f"below the altitude floor safety.z_max_m = {sf.z_max_m:g}")
            if sf.z_min_m is not None and later[2] < sf.z_min_m:
                raise ConfigError(f"scenario.targets[{j}]", later, f"above the ceiling safety.z_min_m = {sf.z_min_m:g}")
        point = self.recovery.fallback_point_ned_m
        for k, target in enumerate(s.legs()):
            if point is not None and math.dist(point[:2], target[:2]) <= bc:
                raise ConfigError("recovery.fallback_point_ned_m", point,
                                  f"inside the keep-out of scenario.targets[{k}] ({math.dist(point[:2], target[:2]):.2f} m "
                                  f"from it horizontally, b*c = {bc:g} m)")
        if not 1.0 / self.carrier.rate_hz <= m.carrier_timeout_s / 2:
            raise ConfigError("carrier.rate_hz", self.carrier.rate_hz,
                              f"too slow for mission.carrier_timeout_s = {m.carrier_timeout_s:g} s "
                              "(at least two states per timeout)")

    def _deck_fields(self, dock_field: str, dock_offset: list[float], deck_z: float) -> None:
        """Riding on the deck (mission.ride = "deck"): the deck (the dock point ``dock_offset`` [m] NED, field
        ``dock_field``, at ``deck_z``) above the altitude floor, the arming lead inside PX4's preflight auto-disarm
        with room for the prestream, the glide path inside the deck's funnel."""
        m, sf, r = self.mission, self.safety, self.recovery
        if sf.z_max_m is not None and deck_z > sf.z_max_m - 0.1:
            raise ConfigError(dock_field, dock_offset,
                              f"with mission.ride = \"deck\" the dock point is the deck, at z {deck_z:g} NED: it must be at "
                              f"least 0.1 m above the altitude floor safety.z_max_m = {sf.z_max_m:g} (the landing "
                              "presses the reference 0.1 m into the deck)")
        if not m.arm_lead_s > m.prestream_s + 0.5:
            raise ConfigError("mission.arm_lead_s", m.arm_lead_s,
                              f"must exceed mission.prestream_s + 0.5 s = {m.prestream_s + 0.5:g} s (the stream, the arming "
                              "and the switch to OFFBOARD come before the separation)")
        if m.final_action == "return":
            glide = 1.0 / math.tan(math.radians(r.glide_angle_deg))
            if not m.deck_clear_slope > glide:
                raise ConfigError("mission.deck_clear_slope", m.deck_clear_slope,
                                  f"must exceed the glide path's {glide:.2f} m across per m down "
                                  f"(recovery.glide_angle_deg = {r.glide_angle_deg:g}): the approach would cross the "
                                  "deck's keep-out")


def _error_from_validation(exc: ValidationError) -> ConfigError:
    err = exc.errors()[0]
    loc = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in err["loc"] if p != "__root__").lstrip(".")
    ctx_error = (err.get("ctx") or {}).get("error")
    if isinstance(ctx_error, ConfigError):
        return ctx_error
    rule = err["msg"].removeprefix("Value error, ")
    if err["type"] == "extra_forbidden":
        rule = "unknown field (check spelling; see configs/ for examples)"
    return ConfigError(loc or "config", err.get("input"), rule)


def from_dict(data: dict[str, Any]) -> Config:
    """Validate a nested dict into a :class:`Config`, raising :class:`ConfigError`."""
    try:
        return Config.model_validate(data)
    except ValidationError as exc:
        raise first_target_named(_error_from_validation(exc), data) from None
    except ConfigError as exc:
        raise first_target_named(exc, data) from None


def load_config(path: str | Path) -> Config:
    """Read and validate a TOML file. Raises :class:`ConfigError` naming the field."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ConfigError("config", str(path), "file not found") from None
    except OSError as exc:  # a directory, no permission, a name too long...
        raise ConfigError("config", str(path)[:200], f"cannot read: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError("config", str(path), f"not UTF-8 (byte {exc.start}: {raw[exc.start:exc.start + 1]!r})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError("config", str(path), f"not valid TOML: {exc}") from None
    return from_dict(data)


def with_overrides(cfg: Config, overrides: dict[str, Any]) -> Config:
    """A copy of ``cfg`` with dotted-key overrides (``{"mavlink.url": "udpin:..."}``, None: left
    as is), revalidated. What the file left to its defaults stays unset in the copy
    (:func:`mission.config.required.stated` still tells)."""
    data = cfg.model_dump(exclude_unset=True)
    if overrides.get("scenario.targets") is not None and overrides.get("scenario.target") is None:
        data.get("scenario", {}).pop("target", None)  # derived from the old targets: the new first one stands
    for key, value in overrides.items():
        if value is None:
            continue
        node = data
        *parents, leaf = key.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    return from_dict(data)
