"""The fixed parameters of a flight and of a simulation, built from a configuration.

:func:`model_from_config` gives the :class:`mission.core.tick.TickModel` (law, target, obstacles,
both safety filters, separation latch) that the realtime controller and the batch simulator
(:mod:`sim.batch.closed_loop`) share; :func:`mission_model` adds what only a flight has (docking,
tracking, arrival, timeouts, the command filter) as a :class:`mission.phases.MissionModel`.

A tunable is declared once, in the schema (:mod:`mission.config.schema`): a runtime field that a
section has by the same name (the same quantity in the same unit) is taken from it by
:func:`derived`; only the fields renamed, converted or computed are written out below. The
runtime models carry no default of a field built from the configuration.
"""
from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
from pydantic import BaseModel

from mission.config.recovery import RecoverySection
from mission.config.schema import Config
from mission.config.vision import marker_offset_ned_m
from mission.errors import ConfigError
from mission.core.docking import DockingGeometry
from mission.core.pursuit import PursuitLimits
from mission.phases import MissionModel
from mission.phases.types import DeckRide, QueueModel, RecoveryModel, RelnavGates
from mission.core.safety import SafetyConfig
from mission.core.tick import SeparationSpeed, TickModel, target_keep_outs
from mission.core.tracking import TrackingGains

if TYPE_CHECKING:
    from mission.vision.detect import MarkerDetector

T = TypeVar("T")

COMMAND_MARGIN_FACTOR = 0.5  # the command filter's obstacle margin, of safety.margin_m
COMMAND_SPEED_FACTOR = 1.25  # its speed limit, of the reference's (room to pull onto the reference)
COMMAND_ACCEL_FACTOR = 1.5  # its acceleration limit, of the reference's
DOCK_CHASE_GAIN_PER_S = 4.0  # [1/s] the riding reference's pull per metre near the dock point it chases (flying.riding)


def model_from_config(cfg: Config, target: np.ndarray | None = None) -> TickModel:
    """The :class:`TickModel` a configuration describes (``target`` overrides, e.g. a batch): one
    passenger's, so not a whole team's (:mod:`mission.config.passenger` derives each passenger's)."""
    if cfg.team.passengers:
        raise ConfigError("team.passengers", [p.name for p in cfg.team.passengers], "a [team]'s configuration is "
                          "flown one passenger at a time (`marsupial run --passenger NAME`, docs/team.md)")
    s = cfg.scenario
    law = cfg.law.params()
    aim = np.asarray(s.target if target is None else target, dtype=float)
    others = None
    if cfg.carrier.avoid_other_targets and aim.ndim == 1 and len(s.legs()) > 1:
        # the other legs' targets: kept b c away by the carrier's barrier rows (its P3 guard's
        # circles lie inside), so that it steers round them instead of braking at them
        rest = [np.asarray(t, dtype=float) for t in s.legs() if not np.allclose(np.asarray(t, dtype=float), aim)]
        planar = bool(s.planar_carrier and s.dim == 3) or s.dim == 2
        others = target_keep_outs(rest, law.separation_distance_m, planar, float(s.carrier_start[-1]) if s.dim == 3 else 0.0)
    return TickModel(
        law=law,
        target=aim,
        obstacles=s.obstacle_set(),
        passenger_safety=cfg.safety.passenger(),
        carrier_safety=cfg.safety.carrier(),
        planar_carrier=bool(s.planar_carrier and s.dim == 3),
        carrier_mode=s.carrier_mode,
        departure_margin_m=cfg.law.departure_margin_m,
        filter_carrier=cfg.safety.filter_carrier,
        other_keep_outs=others,
        separation_speed=None if cfg.carrier.separation_speed_m_s <= 0 else SeparationSpeed(
            cfg.carrier.separation_speed_m_s, cfg.carrier.separation_decel_m_s2,
            law.separation_distance_m + cfg.carrier.separation_room_m),
    )


def mission_model(cfg: Config) -> MissionModel:
    """The phases' fixed parameters from a configuration (3D, local NED)."""
    if cfg.scenario.dim != 3:
        raise ConfigError("scenario.dim", cfg.scenario.dim, "a flight needs dim = 3 (local NED)")
    tick = model_from_config(cfg)
    s = cfg.safety
    ref_speed = s.passenger_max_speed_m_s
    command = SafetyConfig(
        cbf_gain=s.cbf_gain, margin_m=s.margin_m * COMMAND_MARGIN_FACTOR,
        max_speed_m_s=None if ref_speed is None else ref_speed * COMMAND_SPEED_FACTOR,
        max_accel_m_s2=None if s.passenger_max_accel_m_s2 is None else s.passenger_max_accel_m_s2 * COMMAND_ACCEL_FACTOR,
        z_min_m=s.z_min_m, z_max_m=s.z_max_m,
    )
    ride = s.riding_max_accel_m_s2  # riding: the reference's and the command's acceleration limits, as flying's
    riding = None if ride is None else dataclasses.replace(tick.passenger_safety, max_accel_m_s2=ride)
    riding_command = None if ride is None else dataclasses.replace(command, max_accel_m_s2=ride * COMMAND_ACCEL_FACTOR)
    m = cfg.mission
    tracking = derived(TrackingGains, m, kind=m.setpoint, position_gain_per_s=m.track_gain,
                       accel_limit_m_s2=command.max_accel_m_s2, slow_lag_m=m.reference_slow_lag_m,
                       stop_lag_m=m.reference_stop_lag_m)
    model = derived(
        MissionModel, m, tick=tick, command_safety=command,
        dock_offset_ned_m=np.asarray(m.dock_offset_ned_m, dtype=float), dt_s=1.0 / m.rate_hz, tracking=tracking, carrier_dt_s=1.0 / cfg.carrier.rate_hz,
        join_settle_m=min(m.dock_tolerance_m, m.join_settle_m if m.join_settle_m is not None else m.dock_tolerance_m),
        recovery=recovery_model(cfg) if m.final_action == "return" else None,
        queue=queue_model(cfg) if m.final_action == "return" else None,
        leg_start_m=tick.law.separation_distance_m + m.leg_start_margin_m,
        riding_safety=riding, riding_command_safety=riding_command,
        dock_chase=PursuitLimits(m.dock_rejoin_speed_m_s, s.passenger_max_accel_m_s2 or math.inf, DOCK_CHASE_GAIN_PER_S),
        deck=derived(DeckRide, m, keep_out_radius_m=m.deck_keep_out_radius_m, slope=m.deck_clear_slope,
                     clear_height_m=m.deck_clear_height_m, press_floor_m=m.deck_press_floor_m,
                     radius_m=cfg.recovery.deck_radius_m) if m.ride == "deck" else None,
        relnav=derived(RelnavGates, cfg.relnav, params=cfg.relnav.params(), marker_offset_ned_m=np.asarray(
            marker_offset_ned_m(cfg.vision, m.dock_offset_ned_m), dtype=float),
            carrier_accel_m_s2=cfg.relnav.velocity_slew_m_s2 or s.carrier_max_accel_m_s2,
            deck_radius_m=cfg.recovery.deck_radius_m, carrier_law_own_frame=cfg.carrier.p3_frame == "own")
        if cfg.relnav.enabled else None,
    )
    legs = cfg.scenario.legs()
    if len(legs) == 1:
        return model
    targets = [np.asarray(t, dtype=float) for t in legs]
    per_leg = tuple(dataclasses.replace(model, tick=model_from_config(cfg, target=t),
                                        next_target=targets[k + 1] if k + 1 < len(targets) else None)
                    for k, t in enumerate(targets))
    return dataclasses.replace(model, legs=per_leg)


def docking_geometry(r: RecoverySection) -> DockingGeometry:
    """The recovery's geometry from ``[recovery]`` (angles to radians)."""
    return derived(DockingGeometry, r, glide_angle_rad=math.radians(r.glide_angle_deg),
                   cone_half_angle_rad=math.radians(r.cone_half_angle_deg))


def recovery_model(cfg: Config) -> RecoveryModel:
    """The recovery's fixed parameters from ``[recovery]`` (angles to radians; the keep-out is b c)."""
    r = cfg.recovery
    return derived(
        RecoveryModel, r, geometry=docking_geometry(r),
        returning=PursuitLimits(r.return_speed_m_s, r.accel_m_s2),
        approach=PursuitLimits(r.approach_speed_m_s, r.accel_m_s2),
        carrier_max_turn_rate_rad_s=math.radians(r.carrier_max_turn_rate_deg_s),
        fallback_point_ned_m=None if r.fallback_point_ned_m is None else np.asarray(r.fallback_point_ned_m, dtype=float),
        at_target_s=cfg.mission.at_target_s, keep_out_m=cfg.law.params().separation_distance_m)


def queue_model(cfg: Config) -> QueueModel:
    """The recovery queue's parameters from ``[team]``'s scalars (a passenger's configuration keeps
    them, :func:`mission.config.team.passenger_data`), ``[recovery]`` and ``[safety]``."""
    t = cfg.team
    return QueueModel(distance_m=t.queue_distance_m, height_m=t.queue_height_m, timeout_s=t.queue_timeout_s,
                      must_pct=cfg.recovery.battery_reserve_pct + t.queue_battery_pct, rank=cfg.mavlink.target_system,
                      deck_clearance_m=t.passenger_span_m,
                      separation_m=cfg.safety.passenger_separation_m + cfg.safety.margin_m)


def same_named(model: type, section: BaseModel) -> list[str]:
    """The fields of the runtime dataclass ``model`` that the configuration ``section`` has by the
    same name."""
    return [f.name for f in dataclasses.fields(model) if f.init and f.name in type(section).model_fields]


def derived(model: type[T], section: BaseModel, **explicit: Any) -> T:
    """A ``model`` (a runtime dataclass) from a configuration ``section``: each field the section
    has by the same name takes the section's value, unless ``explicit`` converts it; ``explicit``
    gives the others (renamed, converted, computed)."""
    return model(**{name: getattr(section, name) for name in same_named(model, section) if name not in explicit},
                 **explicit)


def vision_detector(cfg: Config) -> MarkerDetector:
    """The marker detector of ``cfg.vision``: its camera (from the calibration file, else the
    ideal pinhole of its field of view) on its mount, its marker layout and its gates."""
    from mission.vision.camera import CameraModel, Mount  # OpenCV: loaded only when used
    from mission.vision.capture import load_calibration
    from mission.vision.detect import DetectorSettings, MarkerDetector
    from mission.vision.layout import MarkerLayout

    v = cfg.vision
    mount = Mount.downward(v.mount_offset_body_m, *v.mount_rpy_deg)
    camera = (load_calibration(v.calibration_file, mount) if v.calibration_file is not None
              else CameraModel.from_fov(v.width_px, v.height_px, v.hfov_deg, mount))
    layout = (MarkerLayout.bundle(v.tag_size_m, v.small_tag_size_m, big_id=v.tag_id, small_id=v.small_tag_id)
              if v.layout == "bundle" else MarkerLayout.single(v.tag_size_m, v.tag_id))
    return MarkerDetector(camera, layout, derived(DetectorSettings, v))
