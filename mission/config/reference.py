"""The configuration reference, generated from the schema (``marsupial config``).

Names, types, defaults and constraints come from the pydantic JSON schema of
:class:`mission.config.schema.Config`; the meaning and unit of a field come from its schema
``description`` when it has a complete one, else from :data:`DOCS` below. A test
(``tests/unit/test_config_reference.py``) fails when a field has neither, and keeps docs/configuration.md's
table identical to :func:`markdown_table`. Units in square brackets; ``[-]`` is dimensionless.
"""
from __future__ import annotations

import json
from typing import Any

from mission.config.schema import Config

# Meaning and unit of each field, where the schema's own description does not say both.
DOCS: dict[str, str] = {
    "law.k_c": "[1/s] carrier gain: u_c = k_c e_tc while the passenger is docked (paper eq. 4)",
    "law.k_p": "[1/(m^3 s)] passenger gain: P = k_p (a - L)(a + d)(a - L/b + c) is in 1/s (paper eq. 6)",
    "law.b": "[-] shape of the potential, > 1; separation when the carrier is within b c of the target",
    "law.c": "[m] shape of the potential; b c is the separation distance (8 m with the paper's values)",
    "law.d": "[m] shape of the potential (paper eq. 6)",
    "law.departure_margin_m": "[m] separation fires at |e_tc| = b c - this (the paper's T+), in flights and simulations",
    "scenario.dim": "[-] 2 (planar) or 3; a flight needs 3",
    "scenario.frame": "[-] `local_ned` (PX4's local NED, z down; plots show altitude) or `xyz` (plots only)",
    "scenario.carrier_start": "[m] carrier position at t = 0 (dim components; the carrier simulator starts here)",
    "scenario.target": "[m] target position (dim components); in 3D with a planar carrier at most b c above the carrier's plane",
    "scenario.passenger_start": "[m] passenger start for `simulate` (default: docked on the carrier, Assumption 2); `run` uses the vehicle's real position",
    "scenario.planar_carrier": "[-] the carrier moves in its horizontal plane (u_c projected onto it) in 3D",
    "scenario.eta": "[m] Assumption 1 lower bound, b c < eta <= |e_tc(0)| (default |e_tc(0)|)",
    "scenario.carrier_mode": "[-] after separation the carrier `stop`s, or keeps its own plan (`remark1`: its velocity of the separation instant, CBF-filtered)",
    "scenario.obstacles": "[-] list of `{ center = [m], radius = m }` circles (2D) or spheres (3D); the carrier avoids their planar circles",
    "scenario.obstacles[].center": "[m] obstacle centre (dim components)",
    "scenario.obstacles[].radius": "[m] obstacle radius",
    "safety.cbf_gain": "[1/s] class-K gain of the control barrier functions",
    "safety.margin_m": "[m] clearance kept from every obstacle surface (reference; the command filter keeps half)",
    "safety.passenger_max_speed_m_s": "[m/s] passenger speed limit, direction kept (off when left out: the paper's unsaturated law)",
    "safety.passenger_max_accel_m_s2": "[m/s^2] passenger acceleration limit; also shapes arrival (speed <= sqrt(2 a |e_pt|))",
    "safety.carrier_max_speed_m_s": "[m/s] carrier speed limit in the law's command",
    "safety.carrier_max_accel_m_s2": "[m/s^2] carrier acceleration limit in the law's command",
    "safety.z_min_m": "[m] NED z lower bound for the passenger (a ceiling: z >= z_min_m)",
    "safety.z_max_m": "[m] NED z upper bound for the passenger (an altitude floor: z <= z_max_m, e.g. -0.5 = 0.5 m up)",
    "safety.filter_carrier": "[-] pass the carrier's command through the CBF filter too",
    "sim.dt_s": "[s] step of the simulated digital controller (command held over it)",
    "sim.duration_s": "[s] simulated time from the start of riding (t = 0)",
    "sim.p1_tolerance_m": "[m] |e_pc| counted as 'on the carrier' before separation (P1)",
    "sim.p2_tolerance_m": "[m] final |e_pt| counted as 'at the target' (P2); a mission config uses mission.arrival_radius_m",
    "monte_carlo.distance_m": "[m] range of the random targets' horizontal distance from the carrier (raised above b c)",
    "monte_carlo.height_m": "[m] range of the random targets' height above the carrier's plane (3D; clipped to 0.95 b c)",
    "mission.rate_hz": "[Hz] controller tick and setpoint rate (PX4 needs > 2 Hz in OFFBOARD)",
    "mission.dock_offset_ned_m": "[m] NED offset of the dock point from the carrier's reported position (the passenger rides there; -1.5 = 1.5 m above)",
    "mission.dock_tolerance_m": "[m] how far from the dock point the vehicle may be at start-up (horizontally) and while riding (P1)",
    "mission.track_gain": "[1/s] pull of the vehicle onto the reference: u = u_ref + gain (x_ref - x_p)",
    "mission.join_speed_m_s": "[m/s] speed of the reference from take-over to the dock point (JOIN)",
    "mission.arrival_radius_m": "[m] distance to the target that counts as arrived (P2)",
    "mission.arrival_dwell_s": "[s] time the vehicle must stay within the arrival radius",
    "mission.final_action": "[-] after arrival: `hold` (PX4 Hold, armed in the air) or `land`",
    "mission.carrier_timeout_s": "[s] a carrier state older than this before separation aborts (carrier_lost)",
    "mission.heartbeat_timeout_s": "[s] vehicle lost when HEARTBEAT and telemetry are silent this long (MAVSDK: 3 s)",
    "mission.prestream_s": "[s] zero-velocity setpoints streamed before asking for OFFBOARD (PX4 refuses OFFBOARD without a stream)",
    "mission.command_retries": "[-] tries of each vehicle command (arm, OFFBOARD, Hold, Land) before giving up",
    "mission.max_duration_s": "[s] mission timeout: Hold after this long",
    "mission.connect_timeout_s": "[s] how long `run` waits for the vehicle and the carrier before giving up (it counts down)",
    "mission.log_dir": "[-] directory of flight logs (`<log_dir>/<time>-<pair>/`)",
    "mavlink.url": "[-] vehicle endpoint: udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT or a serial device /dev/ttyACM0:921600",
    "mavlink.target_system": "[-] MAVLink system id of the vehicle (default: the first that sends HEARTBEAT)",
    "mavlink.source_system": "[-] our MAVLink system id",
    "mavlink.source_component": "[-] our MAVLink component id (191: onboard computer)",
    "mavlink.signing_key_file": "[-] MAVLink 2 signing key file (64 hex digits or 32 bytes); everything sent is signed",
    "zenoh.mode": "[-] Zenoh session mode: `peer`, `client` or `router`",
    "zenoh.listen": "[-] Zenoh endpoints to listen on, e.g. `tcp/127.0.0.1:7450`",
    "zenoh.connect": "[-] Zenoh endpoints to connect to, e.g. `tcp/127.0.0.1:7447` (a router)",
    "zenoh.multicast_scouting": "[-] find peers by UDP multicast (off: loopback only, explicit endpoints)",
    "zenoh.config_file": "[-] a Zenoh JSON5 config file as the base (see configs/zenoh/); listen/connect still override",
    "zenoh.pair": "[-] pair name: the key namespace `marsupial/<pair>/...` (letters, digits, _ and -)",
    "zenoh.encoding": "[-] carrier state encoding: `json` or `cdr` (ROS 2 nav_msgs/Odometry)",
    "zenoh.rendezvous": "[-] peers with no endpoints meet on this loopback endpoint (the first process listens); none: ephemeral listener only",
    "zenoh.carrier_key": "[-] override of the carrier state key, e.g. `robot1/odom` (zenoh-bridge-ros2dds) or `0/odom/nav_msgs::msg::dds_::Odometry_/*` (rmw_zenoh)",
    "carrier.backend": "[-] the carrier robot `marsupial carrier` drives: `sim` (built-in kinematic robot), `mavlink` (PX4 rover/boat), `ros2` (ROS 2 robot over Zenoh)",
    "carrier.rate_hz": "[Hz] carrier controller's tick and publish rate (the built-in robot integrates at it; simulated time)",
    "carrier.max_speed_m_s": "[m/s] carrier speed limit in the law's command (with safety.carrier_max_speed_m_s)",
    "carrier.passenger_timeout_s": "[s] a passenger status older than this (or a lost liveliness token) stops an approaching carrier",
    "carrier.kinematics": "[-] what the carrier can follow: `holonomic` (any planar velocity), `diff_drive` or `ackermann` (tracking law: speed scaled by the heading error, yaw rate to the bearing)",
    "carrier.max_yaw_rate_rad_s": "[rad/s] tracking law: yaw rate limit",
    "carrier.min_speed_fraction": "[-] tracking law, Ackermann: fraction of the speed kept while misaligned (it turns only while moving)",
    "carrier.wheelbase_m": "[m] tracking law, Ackermann: wheelbase (yaw rate <= v tan(max_steer) / wheelbase)",
    "carrier.velocity_bias_tau_s": "[s] the carrier publishes its velocity plus the low-passed (this time constant) difference between its position's rate and its estimator's velocity, so the passenger's feed-forward moves as the dock does (a PX4 rover's EKF position ran 0.1-0.3 m/s faster than its velocity); 0 off",
    "carrier.start_accel_m_s2": "[m/s^2] the carrier's gentle start: while it is measured slower than 0.15 m/s its command's speed grows at most this fast (stiction: it breaks free at a low command, not leaping to a high one); 0 off",
    "carrier.max_steer_rad": "[rad] tracking law, Ackermann: steering angle limit",
    "carrier.mavlink": "[-] table: the PX4 vehicle of the `mavlink` backend",
    "carrier.mavlink.url": "[-] the carrier vehicle's endpoint (as mavlink.url); PX4 SITL instance i sends to 14540 + i",
    "carrier.mavlink.target_system": "[-] MAVLink system id of the carrier vehicle (PX4 SITL instance i: i + 1); default: the first PX4 heard",
    "carrier.mavlink.source_system": "[-] our MAVLink system id on that link (default: target_system, else 1)",
    "carrier.mavlink.source_component": "[-] our MAVLink component id (191: onboard computer)",
    "carrier.mavlink.signing_key_file": "[-] MAVLink 2 signing key file of the carrier's link",
    "carrier.mavlink.heartbeat_timeout_s": "[s] the carrier vehicle counts as lost after this long without HEARTBEAT (stop)",
    "carrier.mavlink.shared_origin": "[deg, deg, m] lat, lon, alt AMSL of the shared frame's origin; when set the offset comes from the vehicle's EKF origin (GPS_GLOBAL_ORIGIN)",
    "carrier.ros2": "[-] table: the ROS 2 robot of the `ros2` backend",
    "carrier.ros2.key_form": "[-] `ros2dds` (zenoh-bridge-ros2dds: `<ns>/odom`) or `rmw_zenoh` (`<domain>/<ns>/odom/<type>/<hash>`)",
    "carrier.ros2.namespace": "[-] ROS namespace of the robot's topics",
    "carrier.ros2.domain_id": "[-] ROS_DOMAIN_ID (rmw_zenoh keys start with it)",
    "carrier.ros2.odom_topic": "[-] nav_msgs/Odometry topic (ENU, REP 103) the carrier reads",
    "carrier.ros2.cmd_vel_topic": "[-] geometry_msgs/Twist topic (body FLU) the carrier commands",
}


def _resolve(schema: dict[str, Any], node: dict[str, Any]) -> dict[str, Any]:
    ref = node.get("$ref")
    return schema["$defs"][ref.rsplit("/", 1)[1]] if ref else node


def _type(schema: dict[str, Any], p: dict[str, Any]) -> str:
    if "anyOf" in p:
        kinds = [_type(schema, q) for q in p["anyOf"]]
        return " or ".join(k for k in kinds if k != "null") + (" or none" if "null" in kinds else "")
    if "enum" in p:
        return " \\| ".join(json.dumps(v) for v in p["enum"])
    if "const" in p:
        return json.dumps(p["const"])
    if "$ref" in p:
        return "table"
    kind = p.get("type", "any")
    if kind == "array":
        if "prefixItems" in p:
            return f"[{', '.join(_type(schema, q) for q in p['prefixItems'])}]"
        return f"list of {_type(schema, p.get('items', {}))}"
    return {"number": "float", "integer": "int", "string": "str", "boolean": "bool", "null": "null"}.get(kind, kind)


def _rule(p: dict[str, Any]) -> str:
    parts = []
    for key, op in (("exclusiveMinimum", ">"), ("minimum", ">="), ("exclusiveMaximum", "<"), ("maximum", "<=")):
        for q in [p, *p.get("anyOf", [])]:
            if key in q:
                parts.append(f"{op} {q[key]:g}")
    if "pattern" in p:
        parts.append(f"matches `{p['pattern']}`")
    return ", ".join(parts)


def fields() -> list[dict[str, str]]:
    """One row per configuration field: key, type, default, rule, doc (meaning with its unit)."""
    schema = Config.model_json_schema()
    rows = []

    def walk(prefix: str, model: dict[str, Any]) -> None:
        for name, p in model.get("properties", {}).items():
            key = f"{prefix}{name}"
            items = p.get("items", {})
            desc = p.get("description", "")
            doc = DOCS.get(key) or desc
            rows.append({"key": key, "type": _type(schema, p), "default": json.dumps(p["default"]) if "default" in p else "required",
                         "rule": _rule(p), "doc": doc})
            if "$ref" in items:  # a list of tables (obstacles)
                walk(f"{key}[].", _resolve(schema, items))
            if "$ref" in p:  # a sub-table (carrier.mavlink, carrier.ros2)
                walk(f"{key}.", _resolve(schema, p))

    for section, ref in schema["properties"].items():
        walk(f"{section}.", _resolve(schema, ref))
    return rows


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def markdown_table() -> str:
    """The reference as a Markdown table (docs/configuration.md's *Configuration reference*)."""
    lines = ["| field | type | default | rule | meaning [unit] |", "|---|---|---|---|---|"]
    for r in fields():
        lines.append(f"| `{r['key']}` | {r['type']} | `{r['default']}` | {_cell(r['rule'])} | {_cell(r['doc'])} |")
    return "\n".join(lines)


def text_table() -> str:
    """The reference for a terminal: one block per field."""
    out = []
    for r in fields():
        rule = f", {r['rule']}" if r["rule"] else ""
        out.append(f"{r['key']}  ({r['type']}, default {r['default']}{rule})\n    {r['doc']}")
    return "\n".join(out)


def effective(cfg: Config) -> str:
    """Every field's value in ``cfg`` (file, then defaults), one ``section.field = value`` a line."""
    lines = []
    for section, values in cfg.model_dump(mode="json").items():
        for name, value in values.items():
            lines.append(f"{section}.{name} = {json.dumps(value)}")
    return "\n".join(lines)


def json_schema() -> str:
    return json.dumps(Config.model_json_schema(), indent=2)
