"""``[recovery]``: bringing the passenger home to the moving carrier (``mission.final_action =
"return"``): the return, the holdoff, the approach on the glide path, go-arounds, the fallback and
the battery's say. Part of the schema in :mod:`mission.config.schema`; the phases are described in
docs/recovery.md.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Literal

from pydantic import Field, model_validator

from mission.config.fields import Coord, Section
from mission.errors import ConfigError

if TYPE_CHECKING:
    from mission.config.carrier import CarrierSection


class RecoverySection(Section):
    """How the passenger comes home (used only with ``mission.final_action = "return"``)."""

    return_speed_m_s: float = Field(2.0, gt=0, le=20,
        description="[m/s] top speed of the recovery's reference relative to the carrier (returning, going around)")
    approach_speed_m_s: float = Field(0.6, gt=0, le=5,
        description="[m/s] speed along the glide path relative to the carrier")
    accel_m_s2: float = Field(1.5, gt=0, le=10,
        description=("[m/s^2] acceleration limit of the recovery's reference: a phase switch changes the commanded "
                     "velocity by at most this times the tick"))
    holdoff_distance_m: float = Field(4.0, gt=0, le=100,
        description="[m] the holdoff point sits this far behind the final gate along the carrier's course")
    glide_angle_deg: float = Field(25.0, gt=0, lt=90,
        description=("[deg] descent angle of the glide path from the holdoff point onto the final gate, "
                     "decision_height_m above the dock point"))
    descent_speed_m_s: float = Field(0.3, gt=0, le=2,
        description="[m/s] speed of the final, vertical descent from the gate onto the dock point, relative to the carrier")
    final_descent_speed_m_s: float | None = Field(None, gt=0, le=2,
        description=("[m/s] speed of the descent's last part, from three contact heights (contact_height_m) over "
                     "the dock point, relative to the carrier (unset: descent_speed_m_s). The vehicle's vertical "
                     "speed swings round what the reference asks (its estimate's velocity error, the dock's "
                     "vertical velocity in its frame): asked well under contact_max_vertical_speed_m_s, it crosses "
                     "into the contact band within it"))
    final_lineup_margin: float = Field(0.0, ge=0, lt=1,
        description=("[-] the descent goes below two contact heights over the dock point only lined up with this "
                     "fraction of the contact radius to spare (0.3: within 0.7 contact_radius_m), else it pauses "
                     "there: the estimate's few centimetres and the drift while crossing the last decimetre then "
                     "stay inside the contact radius"))
    final_descent_lag_m: float | None = Field(None, gt=0, le=1,
        description=("[m] below three contact heights over the dock point the descent's reference lies at most this "
                     "far below the vehicle (by its estimate) and waits there (unset: it never waits). PX4 closes the "
                     "position sent with the mission's lead (mission.position_lead): a vehicle its vertical swing left "
                     "0.1-0.15 m above its reference caught up at 0.5-0.7 m/s, into the contact band"))
    gate_timeout_s: float = Field(5.0, gt=0, le=60,
        description="[s] at the gate, the vehicle has this long to line up over the dock point, else it goes around")
    deck_radius_m: float = Field(0.5, gt=0, le=20,
        description="[m] radius of the carrier's deck round the dock point (touching it outside contact is a violation)")
    settle_radius_m: float = Field(0.3, gt=0, le=10,
        description="[m] HOLDOFF -> APPROACH once the vehicle is this close to the holdoff point ...")
    settle_speed_m_s: float = Field(0.25, gt=0, le=5,
        description="[m/s] ... and its offset from that point moving no more than this times the dwell (from its "
                    "positions, not PX4's velocity estimate) ...")
    settle_dwell_s: float = Field(1.0, ge=0, le=60, description="[s] ... for this long")
    settle_carrier_speed_m_s: float = Field(0.0, ge=0, le=50,
        description=("[m/s] ... with the carrier moving at least this fast (0: any speed). A carrier that must first "
                     "turn onto its recovery course from a stop (a PX4 Ackermann rover: 10-15 s) is not on it yet, and "
                     "the holdoff point it gives lies behind its old course"))
    cone_half_angle_deg: float = Field(20.0, gt=0, lt=90,
        description="[deg] half angle of the cone round the glide path (apex at the dock point); outside it: go around")
    cone_min_radius_m: float = Field(0.3, gt=0, le=10, description="[m] the cone's radius at the dock point")
    decision_height_m: float = Field(0.6, gt=0, le=10,
        description=("[m] height above the dock point of the final gate: the vehicle descends below it only lined up "
                     "(the horizontal contact conditions), else it goes around"))
    contact_radius_m: float = Field(0.15, gt=0, le=5,
        description="[m] contact: horizontal distance from the dock point at most this")
    contact_height_m: float = Field(0.1, gt=0, le=5,
        description="[m] contact: vertical distance from the dock point at most this")
    contact_max_horizontal_speed_m_s: float = Field(0.2, gt=0, le=5,
        description="[m/s] contact: horizontal speed relative to the carrier at most this")
    contact_max_vertical_speed_m_s: float = Field(0.5, gt=0, le=5,
        description="[m/s] contact: vertical speed relative to the carrier at most this")
    docked_dwell_s: float = Field(1.0, ge=0, le=60, description="[s] contact held this long counts as docked")
    carrier_max_age_s: float = Field(0.3, gt=0, le=10,
        description=("[s] the age budget of the approach and the contact: a carrier state measured longer ago than "
                     "this (with the clock offset's bound) starts no approach, and on one goes around"))
    carrier_return_max_age_s: float = Field(1.0, gt=0, le=10,
        description=("[s] the age budget of the return, the holdoff and a go-around: a carrier state measured "
                     "longer ago than this (with the clock offset's bound) does not count as fresh (its dock point "
                     "is predicted with its known age until then); none fresh for carrier_lost_s: fall back"))
    carrier_max_accel_m_s2: float = Field(1.5, gt=0, le=50,
        description="[m/s^2] on the approach, the carrier accelerating harder than this: go around")
    carrier_max_turn_rate_deg_s: float = Field(20.0, gt=0, le=360,
        description="[deg/s] on the approach, the carrier's course turning faster than this: go around")
    carrier_rate_window_s: float = Field(1.0, gt=0, le=10,
        description=("[s] the carrier's acceleration and turn rate are the least-squares slopes of its velocity and "
                     "heading over its samples of this long (by their own times): longer averages out more of a "
                     "fused velocity's wobble, and finds a turn later (a steady turn at 1.25 times the limit after "
                     "0.72 of this)"))
    carrier_lost_s: float = Field(3.0, gt=0, le=60,
        description="[s] no fresh carrier state for this long during the recovery: fall back")
    max_attempts: int = Field(3, ge=1, le=20, description="[-] approaches before falling back")
    timeout_s: float = Field(180.0, gt=0, le=3600, description="[s] a recovery not docked this long after it began: fall back")
    fallback: Literal["hold", "land"] = Field("hold",
        description=("[-] when the recovery gives up: `hold` at fallback_height_m, fallback_offset_m off the carrier's "
                     "path, or `land` at fallback_point_ned_m"))
    fallback_point_ned_m: list[Coord] | None = Field(None,
        description="[m] NED point to land at with fallback = `land` (outside the target's b c keep-out)")
    fallback_height_m: float = Field(5.0, gt=0, le=500,
        description="[m] height above the dock point at which the fallback holds (or flies to its landing point)")
    fallback_offset_m: float = Field(6.0, ge=0, le=1000,
        description="[m] the `hold` fallback moves this far off the carrier's path, sideways to its course")
    battery_reserve_pct: float = Field(25.0, ge=0, le=100,
        description=("[%] the passenger is recalled when the battery left, less what returning and docking would use, "
                     "falls to this"))
    docking_budget_s: float = Field(30.0, ge=0, le=600,
        description="[s] flight time the battery rule allows for the holdoff, the approach and one go-around")
    offboard_loss_return: bool = Field(True,
        description=("[-] while the mission flies, PX4's offboard-loss action (COM_OBL_RC_ACT) is Return, put back at "
                     "the end: a controller that dies leaves the passenger flying to its home, kept at the carrier "
                     "(false: the vehicle's own setting; PX4 of 2025 then descends where it is)"))

    @model_validator(mode="after")
    def _geometry(self) -> RecoverySection:
        if not self.holdoff_distance_m > self.deck_radius_m + self.cone_min_radius_m:
            raise ConfigError("recovery.holdoff_distance_m", self.holdoff_distance_m,
                              f"inside the deck: must exceed recovery.deck_radius_m + recovery.cone_min_radius_m "
                              f"= {self.deck_radius_m + self.cone_min_radius_m:g} m")
        if not self.contact_radius_m <= self.deck_radius_m:
            raise ConfigError("recovery.contact_radius_m", self.contact_radius_m,
                              f"larger than the deck (recovery.deck_radius_m = {self.deck_radius_m:g} m)")
        if self.fallback == "land" and self.fallback_point_ned_m is None:
            raise ConfigError("recovery.fallback_point_ned_m", None, "required with recovery.fallback = \"land\"")
        if self.fallback_point_ned_m is not None and len(self.fallback_point_ned_m) != 3:
            raise ConfigError("recovery.fallback_point_ned_m", self.fallback_point_ned_m, "must have 3 components (NED)")
        return self



def check_recovery(r: RecoverySection, c: CarrierSection, *, carrier_max_speed_m_s: float | None,
                   passenger_max_speed_m_s: float | None, final_action: str) -> None:
    """Refuse values that leave the recovery no way to finish (raises :class:`ConfigError` naming
    the field to change): a holdoff that waits for the carrier to drive faster than it ever can
    (its top speed, or with ``mission.final_action = "return"`` its recovery course and legs), a
    carrier the passenger can never catch on that course, and a carrier state age limit on the
    approach shorter than two of the carrier's publish periods (every approach would go around), and
    a window of the carrier's rates (``carrier_rate_window_s``) shorter than two of them.
    ``carrier_max_speed_m_s``, ``passenger_max_speed_m_s``, ``final_action``: the config's
    ``safety.*`` and ``mission.final_action``."""
    top = min(v for v in (c.max_speed_m_s, carrier_max_speed_m_s) if v is not None)
    if r.settle_carrier_speed_m_s > top:
        raise ConfigError("recovery.settle_carrier_speed_m_s", r.settle_carrier_speed_m_s,
                          f"above the carrier's top speed {top:g} m/s (carrier.max_speed_m_s, "
                          "safety.carrier_max_speed_m_s): the holdoff would never settle")
    if not r.carrier_max_age_s >= 2.0 / c.rate_hz:
        raise ConfigError("recovery.carrier_max_age_s", r.carrier_max_age_s,
                          f"must be at least two carrier states (2 / carrier.rate_hz = {2.0 / c.rate_hz:g} s): "
                          "every approach would go around")
    if not r.carrier_rate_window_s >= 2.0 / c.rate_hz:
        raise ConfigError("recovery.carrier_rate_window_s", r.carrier_rate_window_s,
                          f"must be at least two carrier states (2 / carrier.rate_hz = {2.0 / c.rate_hz:g} s): "
                          "half of it must hold two samples to measure a rate")
    if final_action != "return":
        return
    fastest = max([c.recovery_speed_m_s] + [leg[1] for leg in c.recovery_course])
    if r.settle_carrier_speed_m_s > fastest:
        raise ConfigError("recovery.settle_carrier_speed_m_s", r.settle_carrier_speed_m_s,
                          f"above {fastest:g} m/s, the fastest the carrier drives while the passenger comes home "
                          "(carrier.recovery_speed_m_s, carrier.recovery_course): the holdoff would never settle")
    if passenger_max_speed_m_s is not None and not c.recovery_speed_m_s < passenger_max_speed_m_s:
        raise ConfigError("carrier.recovery_speed_m_s", c.recovery_speed_m_s,
                          f"must be below safety.passenger_max_speed_m_s = {passenger_max_speed_m_s:g}: the "
                          "passenger could never catch the carrier on its recovery course")
