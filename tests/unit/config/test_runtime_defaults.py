"""One home for every tunable: the runtime models carry no default that can disagree with the
configuration schema's, and the models built from a default configuration hold the schema's
defaults (mission/model.py derives every field a section has by the same name)."""
from __future__ import annotations

import dataclasses
import math
from typing import Any

import pytest
from pydantic import BaseModel

from mission.carrier.guard import GuardParams
from mission.carrier.tracking import TrackingParams
from mission.config.carrier import CarrierSection
from mission.config.recovery import RecoverySection
from mission.config.relnav import FEED_FIELDS, PHASE_FIELDS, RelnavSection
from mission.config.scenario import ScenarioSection
from mission.config.schema import Config, LawSection, MissionSection, SafetySection, from_dict
from mission.core.docking import DockingGeometry
from mission.core.law import LawParams
from mission.core.pursuit import PursuitLimits
from mission.core.safety import SafetyConfig
from mission.core.tick import TickModel
from mission.core.tracking import TrackingGains
from mission.config.vision import VisionSection
from mission.model import derived, mission_model, same_named
from mission.phases.types import DeckRide, MissionModel, RecoveryModel
from mission.vision.detect import DetectorSettings
from sim.camera.sensor import SensorModel
from mission.relnav.estimator import RelnavParams

# Every runtime model built from the configuration, with the sections it is built from.
RUNTIME: list[tuple[type, tuple[type[BaseModel], ...]]] = [
    (LawParams, (LawSection,)),
    (SafetyConfig, (SafetySection,)),
    (TickModel, (LawSection, SafetySection, ScenarioSection)),
    (TrackingGains, (MissionSection,)),
    (MissionModel, (MissionSection,)),
    (DeckRide, (MissionSection,)),
    (DockingGeometry, (RecoverySection,)),
    (RecoveryModel, (RecoverySection, MissionSection)),
    (PursuitLimits, (RecoverySection,)),
    (GuardParams, (CarrierSection,)),
    (TrackingParams, (CarrierSection,)),
    (DetectorSettings, (VisionSection,)),
    (SensorModel, (VisionSection,)),
    (RelnavParams, (RelnavSection,)),
]


def schema_default(section: type[BaseModel], name: str) -> Any:
    return section.model_fields[name].get_default(call_default_factory=True)


def disagreements(model: type, sections: tuple[type[BaseModel], ...]) -> list[str]:
    """The fields of the dataclass ``model`` that carry a default while one of ``sections`` has a
    field of the same name with another default."""
    found = []
    for f in dataclasses.fields(model):
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            continue
        mine = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[misc]
        for section in sections:
            if f.name in section.model_fields and schema_default(section, f.name) != mine:
                found.append(f"{model.__name__}.{f.name} = {mine!r}, {section.__name__}.{f.name} = "
                             f"{schema_default(section, f.name)!r}")
    return found


def test_no_runtime_default_disagrees_with_the_schema():
    assert [d for model, sections in RUNTIME for d in disagreements(model, sections)] == []


def test_the_models_built_from_the_configuration_carry_no_default_of_their_own():
    """TrackingGains, DockingGeometry, RelnavParams, the camera sensor and the mission's model take every tunable from the schema:
    none of those fields has a second default."""
    for model in (TrackingGains, DockingGeometry, RecoveryModel, RelnavParams, SensorModel):
        assert [f.name for f in dataclasses.fields(model) if f.default is not dataclasses.MISSING] == []
    # the detector's gates that [vision] configures have no second default either
    assert [f.name for f in dataclasses.fields(DetectorSettings)
            if f.name in VisionSection.model_fields and f.default is not dataclasses.MISSING] == []
    built_by_mission_model = {f.name for f in dataclasses.fields(MissionModel)} - {"legs", "next_target"}
    assert [f.name for f in dataclasses.fields(MissionModel)
            if f.name in built_by_mission_model and f.default is not dataclasses.MISSING] == []


def test_the_disagreement_check_can_fail():
    @dataclasses.dataclass(frozen=True)
    class OldGains:  # what TrackingGains said before: a pull of 1/s, no lead
        track_gain: float = 1.0
        position_lead: float = 0.0
        integral_limit: float = 2.0  # agrees
        kind: str = "velocity"  # the schema calls it mission.setpoint: not compared by name

    assert disagreements(OldGains, (MissionSection,)) == [
        "OldGains.track_gain = 1.0, MissionSection.track_gain = 0.0",
        "OldGains.position_lead = 0.0, MissionSection.position_lead = 2.6",
    ]


DEFAULT = from_dict({"mission": {"final_action": "return", "ride": "deck"}})  # the deck and the recovery built too


@pytest.fixture(scope="module")
def default_model() -> MissionModel:
    """The mission model of the default configuration (riding on the deck and coming home)."""
    return mission_model(DEFAULT)


def test_the_default_configuration_gives_the_schemas_defaults(default_model: MissionModel):
    m, r = DEFAULT.mission, DEFAULT.recovery
    assert m.model_fields_set == {"final_action", "ride"} and r == RecoverySection()  # the rest: defaults
    built = [(default_model.tracking, m), (default_model, m), (default_model.deck, m),
             (default_model.recovery, r), (default_model.recovery.geometry, r)]
    for obj, section in built:
        names = same_named(type(obj), section)
        assert names, type(obj).__name__
        for name in names:
            value, default = getattr(obj, name), getattr(section, name)
            if isinstance(default, list):
                value, default = list(value), default  # an array in the runtime model
            assert value == default, f"{type(obj).__name__}.{name}"
    g = default_model.tracking  # the renamed ones
    assert (g.kind, g.position_gain_per_s, g.slow_lag_m, g.stop_lag_m) == (
        m.setpoint, m.track_gain, m.reference_slow_lag_m, m.reference_stop_lag_m)
    geometry = default_model.recovery.geometry
    assert geometry.glide_angle_rad == pytest.approx(math.radians(r.glide_angle_deg))
    assert geometry.cone_half_angle_rad == pytest.approx(math.radians(r.cone_half_angle_deg))
    assert default_model.tick.departure_margin_m == Config().law.departure_margin_m


def test_derived_takes_same_named_fields_and_lets_explicit_ones_convert():
    @dataclasses.dataclass(frozen=True)
    class Runtime:
        track_gain: float
        dock_offset_ned_m: tuple[float, ...]
        rate_s: float

    m = MissionSection(track_gain=0.7)
    built = derived(Runtime, m, dock_offset_ned_m=tuple(m.dock_offset_ned_m), rate_s=1.0 / m.rate_hz)
    assert built == Runtime(0.7, (0.0, 0.0, -1.5), 0.02)
    assert same_named(Runtime, m) == ["track_gain", "dock_offset_ned_m"]


def test_the_relative_estimators_params_are_the_sections():
    section = RelnavSection(gate_nis=9.0)
    tuning = {k: v for k, v in section.model_dump().items() if k not in PHASE_FIELDS + FEED_FIELDS}  # the rest: phases, feeds
    assert dataclasses.asdict(section.params()) == tuning
    assert set(PHASE_FIELDS + FEED_FIELDS) <= set(section.model_dump())
