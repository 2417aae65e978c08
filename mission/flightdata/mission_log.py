"""``flight.mcap``: the mission's flight record as Foxglove messages (a :class:`~mission.record.recorder.RecordSink`).

Each :class:`~mission.record.table.TickRow` becomes, at the row's mission-clock time:

- frame transforms ``map_ned -> <pair>/carrier/base_link_frd`` and ``map_ned ->
  <pair>/passenger/base_link_frd`` (rotated by the robot's heading when the row has one) and
  ``map_ned -> <pair>/dock`` (``foxglove.FrameTransform``; frames: :mod:`mission.flightdata.topics`);
- ``phase`` (JSON, every tick) and a ``foxglove.Log`` line per phase change and event;
- ``distances`` (|e_pc|, |e_tc|, |e_pt| with the dock point as the law's carrier, the carrier's
  own distance to the target, and P), ``command`` (the law's command, the safe command, the
  reference), ``safety`` (the filter's activity), ``setpoint`` (what was sent), and ``record``
  (the CSV row itself, column by column: what :func:`mission.flightdata.read.read_mcap_record`
  reads back);

and once a second of mission clock (and when the anchor latches, or the recovery's course turns):
``map -> map_ned`` (NED under the ENU frame), each robot's ``base_link_frd -> base_link`` (FRD
to FLU), the scene (target, obstacles with their radii, the b c
circle in the dock's plane, the dock point, both robots, the latched anchor, and while a recovery
brings the passenger home its holdoff point and glide path: ``foxglove.SceneUpdate``), and the
carrier feed's and the link's counters. With ``[relnav]`` enabled, each row that carries the
relative estimator's view also becomes a ``relnav`` message (:func:`relnav_message`: the estimate,
its covariance and counts), and each input the estimator was handed since the row before a
``relnav/inputs`` message (:mod:`mission.flightdata.relnav_inputs`: they replay it); the channels
are made on the first such row, so a flight without it has none. Topics and schemas: :mod:`mission.flightdata.topics`.
The camera's frames, when a marker feed hands them over (:meth:`MissionLog.camera`), go to the
camera's channels (:mod:`mission.flightdata.camera_log`).
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Callable

import numpy as np

from mission.core.docking import DockingGeometry, gate_point, holdoff_point
from mission.flightdata.camera_log import CameraLog
from mission.flightdata.relnav_inputs import input_message
from mission.flightdata.topics import (MAP_FRAME, MISSION_CHANNELS, RELNAV_CHANNELS, WORLD_FRAME, flu_frame, frame,
                                      topics)
from mission.flightdata.writer import DataLog, LiveAddress, timestamp
from mission.phases import Phase
from mission.phases.types import RelativeView
from mission.record.table import COLUMNS, TickRow
from mission.relnav.kalman import B_, C_, D_, W_
from mission.vision.camera import SeenFrame

PHASES = [p.value for p in Phase]
COURSE_REDRAW_COS = math.cos(math.radians(2.0))  # the recovery's course turned this much: draw the scene again
NED_IN_ENU = (math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0)  # (x, y, z, w): (n, e, d) -> (e, n, -d)
FLU_IN_FRD = (1.0, 0.0, 0.0, 0.0)  # (x, y, z, w): half a turn about forward


def yaw_quaternion(yaw_rad: float | None) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a heading ``yaw_rad`` [rad] from north, clockwise seen from above: a turn
    about NED's down axis (identity when the heading is unknown or not finite)."""
    if yaw_rad is None or not math.isfinite(yaw_rad):
        return (0.0, 0.0, 0.0, 1.0)
    return (0.0, 0.0, math.sin(yaw_rad / 2.0), math.cos(yaw_rad / 2.0))


# Plain Python on lists below, not numpy on 3-vectors: the worker shares the GIL with the control
# loop, and per-call numpy overhead on tiny arrays was most of its time.
_finite = math.isfinite


def clean(value: Any) -> Any:
    """A JSON-safe value: NaN and infinities become None (JSON has no NaN)."""
    if isinstance(value, float) and not _finite(value):
        return None
    return value


def vector(v: Any) -> dict[str, float] | None:
    """``{"n", "e", "d"}`` of a NED vector (array or sequence), or None when it is missing or not finite."""
    if v is None:
        return None
    n, e, d = v.tolist() if hasattr(v, "tolist") else v
    if not (_finite(n) and _finite(e) and _finite(d)):
        return None
    return {"n": float(n), "e": float(e), "d": float(d)}


def _distance(a: Any, b: Any) -> float | None:
    if a is None or b is None:
        return None
    d = math.dist(a.tolist() if hasattr(a, "tolist") else a, b.tolist() if hasattr(b, "tolist") else b)
    return d if _finite(d) else None


def _block(p: Any, rows: slice, cols: slice) -> list[float] | None:
    """The ``rows`` x ``cols`` block of the matrix ``p`` row-major, or None when any is not finite."""
    values = [float(v) for v in np.asarray(p[rows, cols]).ravel().tolist()]
    return values if all(_finite(v) for v in values) else None


def relnav_message(view: RelativeView) -> dict[str, Any]:
    """The ``marsupial.RelativeEstimate`` message of one tick's :class:`RelativeView`: its
    fields, and from its ``estimate`` (when it has one; else null) the velocities, the
    covariance's blocks (state order: carrier position, velocity, bias, the passenger's drift; the
    velocity's the carrier's in the passenger's frame, its own plus the drift) and the counts."""
    e = view.estimate
    out: dict[str, Any] = {
        "sample_t_s": None, "position": vector(view.position_ned_m), "velocity": None, "carrier_position": None,
        "carrier_velocity": None, "bias": vector(view.bias_ned_m), "pending": vector(view.pending_ned_m),
        "position_covariance_m2": None, "velocity_covariance_m2_s2": None, "bias_covariance_m2": None,
        "position_bias_covariance_m2": None, "position_sigma": None, "position_sigma_m": clean(float(view.position_sigma_m)),
        "converged": bool(view.converged), "since_marker_s": clean(float(view.since_marker_s)),
        "fused": None, "rejected": None, "too_old": None, "too_new": None, "resets": None}
    if e is None:
        return out
    p = e.covariance
    diagonal = np.diag(p)[C_].tolist()
    out.update({
        "sample_t_s": clean(float(e.t_s)), "velocity": vector(e.velocity_ned_m_s),
        "carrier_position": vector(e.carrier_position_ned_m), "carrier_velocity": vector(e.carrier_velocity_ned_m_s),
        "position_covariance_m2": _block(p, C_, C_), "velocity_covariance_m2_s2": _moving_covariance(p),
        "bias_covariance_m2": _block(p, B_, B_), "position_bias_covariance_m2": _block(p, C_, B_),
        "position_sigma": vector([math.sqrt(v) if v >= 0.0 else math.nan for v in diagonal]),
        "fused": dict(e.counts.fused), "rejected": dict(e.counts.rejected), "too_old": e.counts.too_old,
        "too_new": e.counts.too_new, "resets": e.counts.resets})
    return out


def _moving_covariance(p: Any) -> list[float] | None:
    """The covariance [m^2/s^2] of the carrier's velocity in the passenger's frame (its own plus the
    passenger's drift: :mod:`mission.relnav.kalman`) from the filter's ``p``, as :func:`_block`."""
    p = np.asarray(p, dtype=float)
    moving = p[W_, W_] + p[W_, D_] + p[D_, W_] + p[D_, D_]
    return _block(moving, slice(0, 3), slice(0, 3))


def bc_circle(info: dict[str, Any], points: int = 72) -> np.ndarray:
    """The points (points, 3) [m] NED where the dock point is b c from the target: the circle of
    the sphere ``|x_t - dock| = b c`` in the dock's plane (carrier plane + dock offset), the
    passenger's separation line; in the target's horizontal plane when the sphere misses it."""
    target = np.asarray(info["target_ned_m"], dtype=float)
    bc = float(info["bc_m"])
    plane_d = float(info.get("carrier_start_ned_m", [0.0, 0.0, 0.0])[2]) + float(info.get("dock_offset_ned_m", [0, 0, 0])[2])
    height = target[2] - plane_d
    radius = math.sqrt(bc * bc - height * height) if abs(height) < bc else bc
    d = plane_d if abs(height) < bc else target[2]
    a = np.linspace(0.0, 2.0 * math.pi, points, endpoint=False)
    return np.stack([target[0] + radius * np.cos(a), target[1] + radius * np.sin(a), np.full(points, d)], axis=-1)


class MissionLog(DataLog):
    """``flight.mcap`` of pair ``pair`` (and the live view at ``live``) from the flight record's rows.

    ``info``: ``mission.json``'s content (target, obstacles, b c, dock offset); ``clock``: the
    ``clock`` metadata (what the times are). The file also holds ``mission`` (``info``) and, at
    close, ``mission_end`` (final ``mission.json`` and summary values) metadata; each value is JSON.
    """

    def __init__(self, path: str | Path, info: dict[str, Any], *, pair: str, clock: dict[str, str],
                 live: LiveAddress | None = None, docking: DockingGeometry | None = None) -> None:
        super().__init__(path, name=pair, metadata={"clock": clock, "mission": _json_values(info)}, live=live)
        self.pair, self.info = pair, info
        self.topics = topics(pair)
        self.ch = {key: self.channel(self.topics[key], schema) for key, _, schema in MISSION_CHANNELS}
        self.frames = {name: frame(pair, name) for name in ("carrier", "passenger", "dock")}
        self._counters: Callable[[], dict[str, Any]] | None = None
        self._acted = 0
        self._next_periodic_s: float | None = None
        self._anchor: np.ndarray | None = None
        self._circle = bc_circle(info)
        self._target = [float(x) for x in info["target_ned_m"]]
        self._docking = docking
        self._course: np.ndarray | None = None  # the recovery's course the scene was last drawn for
        self.camera_log = CameraLog(pair, self.channel, self.log_ns)
        self._relnav_ch: Any = None  # made on the first row with a relative estimate
        self._inputs_ch: Any = None  # ... and the estimator's inputs (made with it)
        self._inputs = 0  # the estimator's inputs logged so far

    # ---------------------------------------------------------------- RecordSink
    def tick(self, row: TickRow) -> None:
        self.submit(row.t_s, row)

    def set_counters(self, counters: Callable[[], dict[str, Any]]) -> None:
        self._counters = counters

    def camera(self, t_s: float, seen: SeenFrame) -> None:
        """Queue a camera frame that reached the mission at ``t_s`` [s, mission clock] (a
        :class:`~mission.interfaces.CameraSink`; returns at once)."""
        self.submit(t_s, seen)

    def close(self, info: dict[str, Any], summary: dict[str, Any]) -> None:
        """Finish the file with ``mission_end``: ``info`` (the final ``mission.json``) and how the
        mission ended (``summary``'s phase, reason, detail and P1-P3). Idempotent."""
        end = {**info, **{k: v for k, v in summary.items() if k in ("phase", "reason", "detail", "p1", "p2", "p3")}}
        self.finish({"mission_end": _json_values(end)} if end else None)

    # ---------------------------------------------------------------- worker
    def handle(self, t_s: float, row: TickRow | SeenFrame) -> None:
        from foxglove.messages import FrameTransform, Log, LogLevel, Quaternion, Vector3

        if isinstance(row, SeenFrame):
            self.camera_log.handle(t_s, row)
            return

        t = self.log_ns(t_s)
        stamp = timestamp(t)

        def transform(key: str, child: str, v: dict[str, float] | None, yaw_rad: float | None = None) -> None:
            if v is not None:
                x, y, z, w = yaw_quaternion(yaw_rad)
                self.ch[key].log(FrameTransform(timestamp=stamp, parent_frame_id=WORLD_FRAME, child_frame_id=child,
                                                translation=Vector3(x=v["n"], y=v["e"], z=v["d"]),
                                                rotation=Quaternion(x=x, y=y, z=z, w=w)), log_time=t)

        x_c, x_p, dock = vector(row.x_c), vector(row.x_p), vector(row.dock)
        transform("carrier_tf", self.frames["carrier"], x_c, row.yaw_c)
        transform("passenger_tf", self.frames["passenger"], x_p, row.yaw_p)
        transform("dock_tf", self.frames["dock"], dock)
        anchor_new = row.anchor is not None and self._anchor is None
        if anchor_new:
            self._anchor = np.asarray(row.anchor, dtype=float)
        course = None if row.course is None or self._docking is None else np.asarray(row.course, dtype=float)
        turned = (course is None) != (self._course is None) or (
            course is not None and self._course is not None and float(course @ self._course) < COURSE_REDRAW_COS)
        if turned:
            self._course = course
        if self._next_periodic_s is None or t_s >= self._next_periodic_s or anchor_new or turned:
            self._periodic(t, stamp)
            self._next_periodic_s = t_s + 1.0
        for text in row.events:
            level = LogLevel.Error if text.startswith(f"phase {Phase.ABORT.value}") else LogLevel.Info
            self.ch["log"].log(Log(timestamp=stamp, level=level, message=text, name=f"{self.pair}/mission"), log_time=t)
        self.ch["phase"].log({"phase": row.phase, "index": PHASES.index(row.phase) if row.phase in PHASES else -1,
                              "mode": row.mode, "armed": row.armed, "carrier_age_s": clean(row.carrier_age_s)},
                             log_time=t)
        target = self._target
        self.ch["distances"].log({"e_pc_m": _distance(row.x_p, row.dock), "e_tc_m": _distance(target, row.dock),
                                  "e_pt_m": _distance(row.x_p, target), "carrier_target_m": _distance(target, row.x_c),
                                  "bc_m": self.info.get("bc_m"), "P": clean(float(row.P))}, log_time=t)
        self.ch["command"].log({"law": vector(row.desired), "relative": vector(row.relative), "safe": vector(row.u_cmd),
                                "reference_position": vector(row.x_ref), "reference_velocity": vector(row.u_ref)},
                               log_time=t)
        self._acted += int(row.safety_acted)
        self.ch["safety"].log({"acted": row.safety_acted, "acted_ticks": self._acted,
                               "change_m_s": _distance(row.u_cmd, row.desired)}, log_time=t)
        sp = row.setpoint
        self.ch["setpoint"].log({"kind": "none" if sp is None else sp.kind,
                                 "velocity": None if sp is None else vector(sp.velocity_ned_m_s),
                                 "position": None if sp is None else vector(sp.position_ned_m),
                                 "acceleration": None if sp is None else vector(sp.acceleration_ned_m_s2),
                                 "yaw_rad": None if sp is None else clean(sp.yaw_rad)}, log_time=t)
        if row.relnav is not None:
            if self._relnav_ch is None:
                names, schemas = topics(self.pair, RELNAV_CHANNELS), {key: schema for key, _, schema in RELNAV_CHANNELS}
                self._relnav_ch, self._inputs_ch = (self.channel(names[k], schemas[k]) for k in ("relnav", "relnav_inputs"))
            self._relnav_ch.log(relnav_message(row.relnav), log_time=t)
            for item in row.relnav.inputs:
                self._inputs_ch.log(input_message(item, self._inputs), log_time=t)
                self._inputs += 1
        values = row.values()
        values[0] = round(row.t_s, 4)  # as record.csv writes it
        self.ch["record"].log(dict(zip(COLUMNS, [None if type(v) is float and not _finite(v) else v for v in values])),
                              log_time=t)

    def _periodic(self, t: int, stamp: Any) -> None:
        """``map -> map_ned``, the robots' ``base_link_frd -> base_link``, the scene and the
        counters: rarely changing, sent again each second so a viewer that connects late (or
        seeks) has them."""
        from foxglove.messages import FrameTransform, Quaternion, Vector3

        def fixed(parent: str, child: str, q: tuple[float, float, float, float]) -> None:
            self.ch["world_tf"].log(FrameTransform(timestamp=stamp, parent_frame_id=parent, child_frame_id=child,
                                                   translation=Vector3(x=0.0, y=0.0, z=0.0),
                                                   rotation=Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])), log_time=t)

        fixed(MAP_FRAME, WORLD_FRAME, NED_IN_ENU)
        for robot in ("carrier", "passenger"):
            fixed(self.frames[robot], flu_frame(self.pair, robot), FLU_IN_FRD)
        self.ch["scene"].log(self._scene(stamp), log_time=t)
        counters = self._counters() if self._counters is not None else {}
        if "carrier_feed" in counters:
            self.ch["carrier_feed"].log(counters["carrier_feed"], log_time=t)
        if "link" in counters:
            self.ch["link"].log(counters["link"], log_time=t)

    def _scene(self, stamp: Any) -> Any:
        from foxglove.messages import (Color, CubePrimitive, CylinderPrimitive, LinePrimitive, LinePrimitiveLineType,
                                       Point3, Pose, Quaternion, SceneEntity, SceneUpdate, SpherePrimitive,
                                       TextPrimitive, Vector3)

        def pose(p: Any = (0.0, 0.0, 0.0)) -> Pose:
            return Pose(position=Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                        orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))

        def size(a: float, b: float | None = None, c: float | None = None) -> Vector3:
            return Vector3(x=a, y=a if b is None else b, z=a if c is None else c)

        def entity(name: str, frame_id: str = WORLD_FRAME, **shapes: Any) -> SceneEntity:
            return SceneEntity(timestamp=stamp, frame_id=frame_id, id=name, frame_locked=frame_id != WORLD_FRAME, **shapes)

        def label(p: Any, text: str) -> TextPrimitive:
            return TextPrimitive(pose=pose((p[0], p[1], p[2] - 0.8)), billboard=True, font_size=14.0,
                                 scale_invariant=True, color=Color(r=1.0, g=1.0, b=1.0, a=1.0), text=text)

        target = self.info["target_ned_m"]
        entities = [
            entity("target", spheres=[SpherePrimitive(pose=pose(target), size=size(0.6), color=Color(r=0.9, g=0.1, b=0.1, a=1.0))],
                   texts=[label(target, "target")]),
            entity("bc_circle", lines=[LinePrimitive(type=LinePrimitiveLineType.LineLoop, pose=pose(), thickness=2.0,
                                                     scale_invariant=True, points=[Point3(x=float(p[0]), y=float(p[1]), z=float(p[2]))
                                                                                   for p in self._circle],
                                                     color=Color(r=0.9, g=0.6, b=0.1, a=1.0))],
                   texts=[label(self._circle[0], f"b c = {float(self.info['bc_m']):g} m")]),
            entity("carrier", self.frames["carrier"],
                   cubes=[CubePrimitive(pose=pose(), size=size(1.2, 0.8, 0.4), color=Color(r=0.55, g=0.55, b=0.6, a=1.0))]),
            entity("passenger", self.frames["passenger"],
                   cylinders=[CylinderPrimitive(pose=pose(), size=size(0.6, 0.6, 0.15), bottom_scale=1.0, top_scale=1.0,
                                                color=Color(r=0.2, g=0.45, b=0.95, a=1.0))]),
            entity("dock", self.frames["dock"],
                   spheres=[SpherePrimitive(pose=pose(), size=size(0.25), color=Color(r=1.0, g=0.85, b=0.1, a=0.8))]),
        ]
        for i, o in enumerate(self.info.get("obstacles", [])):
            c = list(o["center"]) + [0.0] * (3 - len(o["center"]))
            entities.append(entity(f"obstacle{i}", spheres=[SpherePrimitive(
                pose=pose(c), size=size(2.0 * float(o["radius"])), color=Color(r=0.95, g=0.4, b=0.1, a=0.35))]))
        if self._course is not None and self._docking is not None:
            entities += self._recovery_entities(entity, pose, size, label)
        if self._anchor is not None:
            entities.append(entity("anchor", spheres=[SpherePrimitive(pose=pose(self._anchor), size=size(0.35),
                                                                      color=Color(r=0.1, g=0.8, b=0.3, a=1.0))],
                                   texts=[label(self._anchor, "anchor")]))
        return SceneUpdate(entities=entities)

    def _recovery_entities(self, entity: Any, pose: Any, size: Any, label: Any) -> list[Any]:
        """The holdoff point H and the glide path H -> gate -> dock of the recovery, in the dock's
        frame (they move with the carrier; they turn with its course). They live 1.5 s: the scene
        is sent again each second while the recovery lasts, and they vanish after it."""
        from foxglove.messages import Color, Duration, LinePrimitive, LinePrimitiveLineType, Point3, SpherePrimitive

        assert self._docking is not None and self._course is not None
        origin = np.zeros(3)
        h = holdoff_point(origin, self._course, self._docking)
        gate = gate_point(origin, self._docking)
        path = [Point3(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in (h, gate, origin)]
        lifetime = Duration.from_secs(1.5)
        cyan = {"r": 0.3, "g": 0.85, "b": 0.95}
        return [
            entity("holdoff", self.frames["dock"], lifetime=lifetime, texts=[label(h, "holdoff")],
                   spheres=[SpherePrimitive(pose=pose(h), size=size(0.3), color=Color(**cyan, a=1.0))]),
            entity("glide_path", self.frames["dock"], lifetime=lifetime, lines=[LinePrimitive(
                type=LinePrimitiveLineType.LineStrip, pose=pose(), thickness=2.0, scale_invariant=True, points=path,
                color=Color(**cyan, a=0.9))]),
        ]


def _json_values(values: dict[str, Any]) -> dict[str, str]:
    """MCAP metadata is a string map: each value as JSON."""
    return {k: json.dumps(v, default=str) for k, v in values.items()}
