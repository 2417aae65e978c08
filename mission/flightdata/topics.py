"""Topics, frames and JSON schemas of the flight data (one place: the logs, the layout and the
readers take them from here).

Every topic of a pair starts with ``/<pair>/`` (``/pair0/tf/passenger``), so the files of
several pairs open together and the live servers of ``demo --pairs N`` never clash. Frames, named
as MAVROS and PX4's ROS 2 interface name them: ``map_ned`` is the mission's local NED frame [m]
(PX4's), ``map`` the ENU frame (z up, REP 103) above it that a ROS user and Foxglove's 3D panel
expect; a robot's body is ``<pair>/<robot>/base_link_frd`` (forward-right-down, rotated by its
heading when known) with ``<pair>/<robot>/base_link`` (forward-left-up) under it, for
``<robot>`` ``carrier``, ``passenger`` and ``carrier_own`` (the carrier's state as it used it);
the dock point is ``<pair>/dock`` (in ``map_ned``). Vectors in JSON messages are
``{"n", "e", "d"}`` objects in ``map_ned``; a value that does not exist on a tick is ``null``.
"""
from __future__ import annotations

from typing import Any

from mission.relnav.estimator import KINDS

MAP_FRAME = "map"
WORLD_FRAME = "map_ned"
BODY_FRD = "base_link_frd"
BODY_FLU = "base_link"

# (key, topic after the pair prefix, schema: a Foxglove schema name or a key of JSON_SCHEMAS)
MISSION_CHANNELS = (
    ("world_tf", "tf/world", "foxglove.FrameTransform"),
    ("carrier_tf", "tf/carrier", "foxglove.FrameTransform"),
    ("passenger_tf", "tf/passenger", "foxglove.FrameTransform"),
    ("dock_tf", "tf/dock", "foxglove.FrameTransform"),
    ("scene", "scene", "foxglove.SceneUpdate"),
    ("log", "log", "foxglove.Log"),
    ("record", "record", "marsupial.FlightRecord"),
    ("phase", "phase", "marsupial.Phase"),
    ("distances", "distances", "marsupial.Distances"),
    ("command", "command", "marsupial.Command"),
    ("safety", "safety", "marsupial.SafetyFilter"),
    ("setpoint", "setpoint", "marsupial.Setpoint"),
    ("carrier_feed", "carrier_feed", "marsupial.CarrierFeed"),
    ("link", "link", "marsupial.LinkStatistics"),
)
# The passenger's downward camera, as the marker feed saw it (``vision.log_rate_hz`` frames a
# second): the frame, its calibration (what Foxglove's Image panel projects with) and the marker's
# corners found in it; their frame is the camera's optical frame :func:`camera_frame`.
CAMERA_CHANNELS = (
    ("image", "camera/image", "foxglove.CompressedImage"),
    ("calibration", "camera/calibration", "foxglove.CameraCalibration"),
    ("detections", "camera/detections", "foxglove.ImageAnnotations"),
    ("mount_tf", "tf/camera", "foxglove.FrameTransform"),
)
# The relative estimator's word on the deck each tick (``[relnav]`` enabled: docs/relnav.md); the
# channel exists only in flights that had an estimate.
RELNAV_CHANNELS = (
    ("relnav", "relnav", "marsupial.RelativeEstimate"),
    ("relnav_inputs", "relnav/inputs", "marsupial.RelativeInput"),
)
# The carrier's own (``carrier.mcap``). ``team``: a team's carrier only (a single pair's file has
# no such channel): every passenger as heard and each pair's distance, every step.
CARRIER_CHANNELS = (
    ("tf", "carrier/tf", "foxglove.FrameTransform"),
    ("status", "carrier/status", "marsupial.CarrierStatus"),
    ("log", "carrier/log", "foxglove.Log"),
    ("passenger_feed", "carrier/passenger_feed", "marsupial.PassengerFeed"),
    ("team", "carrier/team", "marsupial.Team"),
)
TEAM_ONLY = frozenset({"team"})  # keys of CARRIER_CHANNELS a single pair's carrier does not declare


def topics(pair: str, channels: tuple[tuple[str, str, str], ...] = MISSION_CHANNELS) -> dict[str, str]:
    """``{key: "/<pair>/<topic>"}`` of ``channels``."""
    return {key: f"/{pair}/{name}" for key, name, _ in channels}


def frame(pair: str, name: str) -> str:
    """A pair's frame id: ``<pair>/<name>`` (dock), or a robot's body ``<pair>/<robot>/base_link_frd``
    for ``name`` carrier, passenger or carrier_own."""
    return f"{pair}/{name}/{BODY_FRD}" if name in ("carrier", "passenger", "carrier_own") else f"{pair}/{name}"


def camera_frame(pair: str) -> str:
    """The passenger camera's optical frame ``<pair>/passenger/camera_optical`` (x right, y down in
    the image, z along the optical axis: OpenCV's and ROS's ``*_optical_frame``), under the
    passenger's ``base_link_frd``."""
    return f"{pair}/passenger/camera_optical"


def flu_frame(pair: str, robot: str) -> str:
    """A robot's forward-left-up body frame ``<pair>/<robot>/base_link`` (under its base_link_frd)."""
    return f"{pair}/{robot}/{BODY_FLU}"


def _number(description: str) -> dict[str, Any]:
    return {"type": ["number", "null"], "description": description}


def _vector(description: str) -> dict[str, Any]:
    return {"type": ["object", "null"], "description": description + " (world, NED)",
            "properties": {a: {"type": "number"} for a in ("n", "e", "d")}}


def _object(title: str, description: str, properties: dict[str, Any]) -> dict[str, Any]:
    return {"title": title, "description": description, "type": "object", "properties": properties}


_COUNTERS = {"type": "object", "additionalProperties": True}


def _matrix(description: str) -> dict[str, Any]:
    return {"type": ["array", "null"], "items": {"type": "number"}, "minItems": 9, "maxItems": 9,
            "description": description + " (3 x 3, row-major, NED axes n, e, d)"}


def _counts(description: str) -> dict[str, Any]:
    return {"type": "object", "description": description,
            "properties": {k: {"type": "integer"} for k in KINDS}}

JSON_SCHEMAS: dict[str, dict[str, Any]] = {
    "marsupial.FlightRecord": _object(
        "marsupial.FlightRecord", "One row of record.csv, column by column (mission.record.table.COLUMNS)",
        {"t_s": _number("[s] mission clock"), "phase": {"type": "string"}}),
    "marsupial.Phase": _object("marsupial.Phase", "The mission phase after the tick, and the vehicle", {
        "phase": {"type": "string", "description": "mission phase (PREFLIGHT .. DONE, ABORT)"},
        "index": {"type": "integer", "description": "the phase's place in mission.phases.Phase (0 = PREFLIGHT)"},
        "mode": {"type": "string", "description": "the vehicle's flight mode"},
        "armed": {"type": "boolean"},
        "carrier_age_s": _number("[s] age of the carrier sample used")}),
    "marsupial.Distances": _object(
        "marsupial.Distances", "The paper's distances; the law's carrier is the dock point (carrier + dock offset)", {
            "e_pc_m": _number("[m] |x_p - dock|: passenger to dock point"),
            "e_tc_m": _number("[m] |x_t - dock|: target to dock point"),
            "e_pt_m": _number("[m] |x_p - x_t|: passenger to target"),
            "carrier_target_m": _number("[m] |x_t - x_c|: target to the carrier itself (P3)"),
            "bc_m": _number("[m] b c: |e_tc| at which the passenger separates"),
            "P": _number("the law's potential gradient P (null outside riding and navigation)")}),
    "marsupial.Command": _object("marsupial.Command", "The law's command, the safe command and the reference", {
        "law": _vector("[m/s] the law's command u_p (before the safety filter)"),
        "relative": _vector("[m/s] the law's u_p - u_c"),
        "safe": _vector("[m/s] the velocity setpoint after the safety filter and tracking"),
        "reference_position": _vector("[m] the reference the vehicle tracks"),
        "reference_velocity": _vector("[m/s] the reference's velocity")}),
    "marsupial.SafetyFilter": _object("marsupial.SafetyFilter", "What the safety filter did", {
        "acted": {"type": "boolean", "description": "a filter (CBF, speed, acceleration, floor) changed the command"},
        "acted_ticks": {"type": "integer", "description": "ticks on which it acted so far"},
        "change_m_s": _number("[m/s] |safe - law| (null when either is missing)")}),
    "marsupial.Setpoint": _object("marsupial.Setpoint", "The setpoint sent to the vehicle (SET_POSITION_TARGET_LOCAL_NED)", {
        "kind": {"type": "string", "description": "full (position, velocity, acceleration), full_horizontal or "
                 "full_vertical (position and acceleration on those axes only; the other axis's are not sent), "
                 "velocity, or none (nothing sent)"},
        "velocity": _vector("[m/s] velocity"),
        "position": _vector("[m] position (full setpoints)"),
        "acceleration": _vector("[m/s^2] acceleration feed-forward (full setpoints)"),
        "yaw_rad": _number("[rad] absolute heading asked (null: keep the vehicle's)")}),
    "marsupial.CarrierFeed": _object("marsupial.CarrierFeed", "The carrier feed's counters (summary.json carrier_feed)", {
        "received": {"type": "integer"}, "accepted": {"type": "integer"}, "dropped": _COUNTERS,
        "rejected_sources": _COUNTERS, "resyncs": {"type": "integer"}}),
    "marsupial.LinkStatistics": _object("marsupial.LinkStatistics", "The MAVLink link's counters (summary.json link)",
                                        {"rx_messages": {"type": "integer"}, "tx_setpoints": {"type": "integer"}}),
    "marsupial.CarrierStatus": _object("marsupial.CarrierStatus", "The carrier controller's step", {
        "mode": {"type": "string", "description": "waiting, approaching, separated, paused, stopped"},
        "hold_reason": {"type": ["string", "null"], "description": "why it does not drive (null: in control)"},
        "published": {"type": "boolean", "description": "its state went out to the passenger"},
        "position": _vector("[m] own position"), "velocity": _vector("[m/s] own velocity"),
        "yaw_rad": _number("[rad] heading"),
        "law_velocity": _vector("[m/s] the filtered law command u_c"),
        "setpoint": _vector("[m/s] the velocity sent to the robot"),
        "speed_m_s": _number("[m/s] forward speed asked"), "yaw_rate_rad_s": _number("[rad/s] yaw rate asked"),
        "guard_active": {"type": "boolean", "description": "the P3 guard cut the command on this step"},
        "guard_active_ticks": {"type": "integer", "description": "steps so far on which it did"},
        "target": _vector("[m] NED the target of the leg the carrier serves"),
        "target_distance_m": _number("[m] |x_t - x_c| to that target")}),
    "marsupial.RelativeEstimate": _object(
        "marsupial.RelativeEstimate", "The relative estimator's estimate this tick (mission.relnav.inputs.RelativeEstimate, "
        "docs/relnav.md); vectors in NED axes, relative ones with no origin", {
            "sample_t_s": _number("[s] mission clock: the vehicle's own sample the estimate is at"),
            "position": _vector("[m] the carrier's reference point minus the vehicle's (deck minus vehicle)"),
            "velocity": _vector("[m/s] its rate: the carrier's velocity minus the vehicle's"),
            "carrier_position": _vector("[m] the carrier's reference point in the passenger's GNSS frame"),
            "carrier_velocity": _vector("[m/s] the carrier's velocity estimate"),
            "bias": _vector("[m] the carrier's GNSS frame minus the passenger's"),
            "pending": _vector("[m] the part of the estimate's jumps the phases' carrier has not taken in yet"),
            "position_covariance_m2": _matrix("[m^2] covariance of position (and of carrier_position)"),
            "velocity_covariance_m2_s2": _matrix("[m^2/s^2] covariance of carrier_velocity (and of velocity)"),
            "bias_covariance_m2": _matrix("[m^2] covariance of bias"),
            "position_bias_covariance_m2": _matrix("[m^2] cross-covariance, rows position, columns bias"),
            "position_sigma": _vector("[m] standard deviation of position per axis (square roots of the diagonal)"),
            "position_sigma_m": _number("[m] the position's largest standard deviation (of its covariance's eigenvalues)"),
            "converged": {"type": "boolean", "description": "position_sigma_m below relnav.converged_sigma_m"},
            "since_marker_s": _number("[s] since the capture of the newest marker fused (null: none yet)"),
            "fused": _counts("measurements fused so far, by kind"),
            "rejected": _counts("measurements the gate rejected so far, by kind"),
            "too_old": {"type": "integer", "description": "measurements older than the history, dropped"},
            "too_new": {"type": "integer", "description": "measurements stamped beyond the history ahead, dropped"},
            "resets": {"type": "integer", "description": "re-initialisations by a run of rejected markers"}}),
    "marsupial.RelativeInput": _object(
        "marsupial.RelativeInput", "One input the relative estimator was handed, in the order handed "
        "(mission.flightdata.relnav_inputs; they replay the estimator: python -m bench.relnav_replay); "
        "vectors in NED axes as lists [n, e, d]", {
            "seq": {"type": "integer", "description": "its place among the flight's inputs (from 0)"},
            "kind": {"type": "string", "description": "own (the vehicle's own sample: it ticks the estimator), "
                     "carrier (its GNSS fix), marker, range (downward), seated (standing on the deck)"},
            "t_s": _number("[s] mission clock: the sample's, fix's or capture's time"),
            "position": {"type": "array", "items": {"type": "number"},
                         "description": "[m] own: the vehicle's position; carrier: the carrier's, in its GNSS frame"},
            "velocity": {"type": "array", "items": {"type": "number"}, "description": "[m/s] own, carrier: velocity"},
            "acceleration": {"type": ["array", "null"], "items": {"type": "number"},
                             "description": "[m/s^2] carrier: the acceleration it measured and sent (null: none)"},
            "offset": {"type": "array", "items": {"type": "number"},
                       "description": "[m] marker, seated: the carrier's reference point minus the vehicle's"},
            "covariance": {"type": "array", "items": {"type": "number"}, "description": "[m^2] marker: 3 x 3, row-major"},
            "range_m": _number("[m] range: straight down"), "sigma_m": _number("[m] range, seated: standard deviation"),
            "deck_top": {"type": "array", "items": {"type": "number"},
                         "description": "[m] range: the deck's top from the carrier's reference point"},
            "deck_radius_m": _number("[m] range: the deck's radius")}),
    "marsupial.Team": _object(
        "marsupial.Team", "A team's passengers as the carrier heard them at its step (mission.carrier.heard), "
        "and every pair's distance at the carrier's clock", {
            "passengers": {"type": "array", "description": "each passenger, the team's order (team.passengers)",
                           "items": _object("marsupial.HeardPassenger", "a passenger's newest status on its feed", {
                               "name": {"type": "string", "description": "team.passengers[].name"},
                               "phase": {"type": ["string", "null"], "description": "its phase (null: not heard)"},
                               "position": _vector("[m] its position as it reported it"),
                               "velocity": _vector("[m/s] its velocity as it reported it"),
                               "age_s": _number("[s] since its status arrived, on the carrier's clock")})},
            "pairs": {"type": "array", "description": "every pair of passengers, the team's order (0-1, 0-2, ..., 1-2, ...)",
                      "items": _object("marsupial.PairDistance", "two passengers' distance", {
                          "a": {"type": "string"}, "b": {"type": "string"},
                          "distance_m": _number("[m] between their positions moved on by their velocities over their "
                                                "ages (null: either unheard, or older than "
                                                "safety.passenger_separation_max_age_s)"),
                          "counted": {"type": "boolean", "description": "the distance exists and either of them flies: "
                                      "it counts for carrier.json's closest_pair"}})},
            "closest_m": _number("[m] the least counted pair distance at this step (null: none counts)"),
            "closest": {"type": ["array", "null"], "items": {"type": "string"},
                        "description": "the names of that pair (null: none counts)"},
            "separation_m": _number("[m] safety.passenger_separation_m: the distance the passengers keep")}),
    "marsupial.PassengerFeed": _object("marsupial.PassengerFeed", "The carrier's passenger feed counters",
                                       {"received": {"type": "integer"}, "accepted": {"type": "integer"}}),
}
