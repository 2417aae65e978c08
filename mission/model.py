"""The fixed parameters of a flight and of a simulation, built from a configuration.

:func:`model_from_config` gives the :class:`mission.core.tick.TickModel` (law, target, obstacles,
both safety filters, separation latch) that the realtime controller and the batch simulator
(:mod:`sim.batch.closed_loop`) share; :func:`mission_model` adds what only a flight has (docking,
tracking, arrival, timeouts, the command filter) as a :class:`mission.phases.MissionModel`.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from mission.config.schema import Config
from mission.errors import ConfigError
from mission.core.docking import DockingGeometry
from mission.core.pursuit import PursuitLimits
from mission.phases import MissionModel
from mission.phases.types import DeckRide, RecoveryModel
from mission.core.safety import SafetyConfig
from mission.core.tick import TickModel
from mission.core.tracking import TrackingGains

COMMAND_MARGIN_FACTOR = 0.5  # the command filter's obstacle margin, of safety.margin_m
COMMAND_SPEED_FACTOR = 1.25  # its speed limit, of the reference's (room to pull onto the reference)
COMMAND_ACCEL_FACTOR = 1.5  # its acceleration limit, of the reference's


def model_from_config(cfg: Config, target: np.ndarray | None = None) -> TickModel:
    """The :class:`TickModel` a configuration describes (``target`` overrides, e.g. a batch)."""
    s = cfg.scenario
    return TickModel(
        law=cfg.law.params(),
        target=np.asarray(s.target if target is None else target, dtype=float),
        obstacles=s.obstacle_set(),
        passenger_safety=cfg.safety.passenger(),
        carrier_safety=cfg.safety.carrier(),
        planar_carrier=bool(s.planar_carrier and s.dim == 3),
        carrier_mode=s.carrier_mode,
        departure_margin_m=cfg.law.departure_margin_m,
        filter_carrier=cfg.safety.filter_carrier,
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
    m = cfg.mission
    model = MissionModel(
        tick=tick, command_safety=command, dock_offset_ned_m=np.asarray(m.dock_offset_ned_m, dtype=float),
        dock_tolerance_m=m.dock_tolerance_m, track_gain=m.track_gain, join_speed_m_s=m.join_speed_m_s,
        arrival_radius_m=m.arrival_radius_m, arrival_dwell_s=m.arrival_dwell_s, final_action=m.final_action,
        carrier_timeout_s=m.carrier_timeout_s, heartbeat_timeout_s=m.heartbeat_timeout_s, prestream_s=m.prestream_s,
        connect_timeout_s=m.connect_timeout_s, max_duration_s=m.max_duration_s, dt_s=1.0 / m.rate_hz,
        tracking=TrackingGains(kind=m.setpoint, position_gain_per_s=m.track_gain, position_lead=m.position_lead,
                               integral_gain=m.integral_gain, integral_limit=m.integral_limit,
                               drag_ff_per_s=m.drag_ff_per_s, integral_window_m=m.integral_window_m,
                               damping_per_s=m.damping_per_s, bias_compensation_s=m.bias_compensation_s,
                               accel_lead_s=m.accel_lead_s, accel_lead_filter_s=m.accel_lead_filter_s,
                               accel_limit_m_s2=command.max_accel_m_s2,
                               slow_lag_m=m.reference_slow_lag_m, stop_lag_m=m.reference_stop_lag_m),
        carrier_dt_s=1.0 / cfg.carrier.rate_hz,
        join_settle_m=min(m.dock_tolerance_m, m.join_settle_m if m.join_settle_m is not None else m.dock_tolerance_m),
        join_settle_s=m.join_settle_s, arrival_max_speed_m_s=m.arrival_max_speed_m_s,
        recovery=recovery_model(cfg) if m.final_action == "return" else None,
        leg_start_m=cfg.law.b * cfg.law.c + m.leg_start_margin_m,
        deck=DeckRide(arm_lead_s=m.arm_lead_s, keep_out_radius_m=m.deck_keep_out_radius_m, slope=m.deck_clear_slope,
                      clear_height_m=m.deck_clear_height_m) if m.ride == "deck" else None,
    )
    legs = cfg.scenario.legs()
    if len(legs) == 1:
        return model
    targets = [np.asarray(t, dtype=float) for t in legs]
    per_leg = tuple(dataclasses.replace(model, tick=model_from_config(cfg, target=t),
                                        next_target=targets[k + 1] if k + 1 < len(targets) else None)
                    for k, t in enumerate(targets))
    return dataclasses.replace(model, legs=per_leg)


def recovery_model(cfg: Config) -> RecoveryModel:
    """The recovery's fixed parameters from ``[recovery]`` (angles to radians; the keep-out is b c)."""
    r = cfg.recovery
    geometry = DockingGeometry(
        holdoff_distance_m=r.holdoff_distance_m, glide_angle_rad=math.radians(r.glide_angle_deg),
        cone_half_angle_rad=math.radians(r.cone_half_angle_deg), cone_min_radius_m=r.cone_min_radius_m,
        decision_height_m=r.decision_height_m, contact_radius_m=r.contact_radius_m, contact_height_m=r.contact_height_m,
        contact_max_horizontal_speed_m_s=r.contact_max_horizontal_speed_m_s,
        contact_max_vertical_speed_m_s=r.contact_max_vertical_speed_m_s)
    return RecoveryModel(
        geometry=geometry,
        returning=PursuitLimits(r.return_speed_m_s, r.accel_m_s2),
        approach=PursuitLimits(r.approach_speed_m_s, r.accel_m_s2),
        descent_speed_m_s=r.descent_speed_m_s, gate_timeout_s=r.gate_timeout_s, settle_radius_m=r.settle_radius_m, settle_speed_m_s=r.settle_speed_m_s, settle_dwell_s=r.settle_dwell_s,
        settle_carrier_speed_m_s=r.settle_carrier_speed_m_s,
        docked_dwell_s=r.docked_dwell_s, carrier_max_age_s=r.carrier_max_age_s,
        carrier_return_max_age_s=r.carrier_return_max_age_s,
        carrier_max_accel_m_s2=r.carrier_max_accel_m_s2,
        carrier_max_turn_rate_rad_s=math.radians(r.carrier_max_turn_rate_deg_s), carrier_lost_s=r.carrier_lost_s,
        max_attempts=r.max_attempts, timeout_s=r.timeout_s, fallback=r.fallback,
        fallback_point_ned_m=None if r.fallback_point_ned_m is None else np.asarray(r.fallback_point_ned_m, dtype=float),
        fallback_height_m=r.fallback_height_m, fallback_offset_m=r.fallback_offset_m,
        battery_reserve_pct=r.battery_reserve_pct, docking_budget_s=r.docking_budget_s,
        at_target_s=cfg.mission.at_target_s, deck_radius_m=r.deck_radius_m,
        keep_out_m=cfg.law.b * cfg.law.c)
