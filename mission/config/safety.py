"""``[safety]``: the CBF filter, the limits and the pairwise separation barrier (part of the
schema in :mod:`mission.config.schema`; pure). Units as each field says; frames: local NED."""
from __future__ import annotations

from typing import TYPE_CHECKING

from pydantic import Field, model_validator

from mission.config.fields import Section
from mission.errors import ConfigError

if TYPE_CHECKING:  # the schema imports no law: the converters below import it when called
    from mission.core.safety import SafetyConfig


class SafetySection(Section):
    """CBF filter and limits; a limit left out is off (the simulator's paper runs)."""

    cbf_gain: float = Field(1.0, gt=0, le=100, description="[1/s] class-K gain of the control barrier functions")
    margin_m: float = Field(0.5, ge=0, le=100,
        description="[m] clearance kept from every obstacle surface (reference; the command filter keeps half)")
    passenger_max_speed_m_s: float | None = Field(None, gt=0, le=100,
        description="[m/s] passenger speed limit, direction kept (off when left out: the paper's unsaturated law)")
    passenger_max_accel_m_s2: float | None = Field(None, gt=0, le=100,
        description="[m/s^2] passenger acceleration limit; also shapes arrival (speed <= sqrt(2 a |e_pt|))")
    riding_max_accel_m_s2: float | None = Field(None, gt=0, le=100,
        description=("[m/s^2] the passenger's acceleration limit while it rides its carrier (RIDING: the reference on "
                     "the dock point, and the command sent, which may change 1.5 times as fast as the reference), "
                     "where it must follow what the carrier does: a rover that sticks and breaks free from a stand "
                     "leaps faster than `passenger_max_accel_m_s2` (docs/relnav.md, \"Riding a rover that leaps\"). "
                     "The separation and everything after keep `passenger_max_accel_m_s2`, so the input's step at "
                     "the separation stays that limit times one tick. None: `passenger_max_accel_m_s2`"))
    carrier_max_speed_m_s: float | None = Field(None, gt=0, le=100,
        description="[m/s] carrier speed limit in the law's command")
    carrier_max_accel_m_s2: float | None = Field(None, gt=0, le=100,
        description="[m/s^2] carrier acceleration limit in the law's command")
    z_min_m: float | None = Field(None, ge=-100_000, le=100_000,
        description="[m] NED z lower bound for the passenger (a ceiling: z >= z_min_m)")
    z_max_m: float | None = Field(None, ge=-100_000, le=100_000,
        description="[m] NED z upper bound for the passenger (an altitude floor: z <= z_max_m, e.g. -0.5 = 0.5 m up)")
    filter_carrier: bool = Field(True, description="[-] pass the carrier's command through the CBF filter too")
    passenger_separation_m: float = Field(3.0, gt=0, le=100,
        description="[m] least distance between two passengers' centres: the pairwise separation barrier keeps each "
                    "at least this far from every other passenger it hears (docs/team.md, \"Keeping passengers apart\")")
    passenger_separation_vertical_m: float | None = Field(None, gt=0, le=100, description="[m] ... and from one "
        "straight above or below (3D: an ellipsoid between; None: passenger_separation_m, a sphere). Heights err twice "
        "as much as positions on GNSS and baro: docs/team.md, \"The vertical margin\"")
    passenger_separation_max_age_s: float = Field(0.5, gt=0, le=10,
        description="[s] an other passenger's shared state older than this is left out of the separation barrier "
                    "(as if absent); a younger one counts as flown on at its velocity over its age")
    passenger_separation_phase_in_s: float = Field(0.5, ge=0, le=10, description="[s] the separation barrier's rows "
        "phase in over this time from the passenger's separation: no jump of the command at the latch (0: at once; docs/team.md)")

    @model_validator(mode="after")
    def _riding(self) -> "SafetySection":
        ride, own = self.riding_max_accel_m_s2, self.passenger_max_accel_m_s2
        if ride is not None and (own is None or ride < own):
            raise ConfigError("safety.riding_max_accel_m_s2", ride,
                              f"must be at least safety.passenger_max_accel_m_s2 (= {own}), which must be set: riding "
                              "follows the carrier, and never limits the passenger more than flying does")
        return self

    def passenger(self) -> SafetyConfig:
        from mission.core.safety import SafetyConfig

        return SafetyConfig(self.cbf_gain, self.margin_m, self.passenger_max_speed_m_s, self.passenger_max_accel_m_s2, self.z_min_m,
                            self.z_max_m, self.passenger_separation_m, self.passenger_separation_max_age_s,
                            self.passenger_separation_phase_in_s, self.vertical_ratio)

    @property
    def vertical_ratio(self) -> float:
        """[-] the pairwise barrier's vertical half-axis over its level one (1: a sphere)."""
        return (self.passenger_separation_vertical_m or self.passenger_separation_m) / self.passenger_separation_m

    def carrier(self) -> SafetyConfig:
        from mission.core.safety import SafetyConfig

        return SafetyConfig(self.cbf_gain, self.margin_m, self.carrier_max_speed_m_s, self.carrier_max_accel_m_s2)
