"""PX4's flight modes by the names PX4 and pymavlink's ``interpret_px4_mode`` print (pure).

The vehicle's mode travels as one of these names (``VehicleState.mode``; a mode PX4 has but we do
not list reads ``"UNKNOWN(0x...)"``). Their MAVLink encoding is :data:`mission.mavlink.px4.MODES`.
"""
from __future__ import annotations

from enum import StrEnum


class FlightMode(StrEnum):
    MANUAL = "MANUAL"
    ALTCTL = "ALTCTL"
    POSCTL = "POSCTL"
    OFFBOARD = "OFFBOARD"
    STABILIZED = "STABILIZED"
    ACRO = "ACRO"
    READY = "AUTO.READY"
    TAKEOFF = "AUTO.TAKEOFF"
    HOLD = "AUTO.LOITER"  # PX4's Hold (MAVSDK ``offboard.stop()`` switches to it)
    MISSION = "AUTO.MISSION"
    RTL = "AUTO.RTL"
    LAND = "AUTO.LAND"

    @property
    def auto(self) -> bool:
        """One of PX4's AUTO modes (the navigator flies)."""
        return self.value.startswith("AUTO.")


#: Modes a pilot flies with sticks.
MANUAL_MODES = frozenset({FlightMode.MANUAL, FlightMode.ALTCTL, FlightMode.POSCTL, FlightMode.STABILIZED, FlightMode.ACRO})
