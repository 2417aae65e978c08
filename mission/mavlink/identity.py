"""Which autopilot is the vehicle: a pure state machine over the PX4 HEARTBEATs heard.

With ``target_system`` set (``mavlink.target_system``), the first HEARTBEAT of a PX4 autopilot
(autopilot 12) of a vehicle type (:data:`VEHICLE_TYPES`) from that system and
``target_component`` identifies it. Unset, a vehicle is adopted only after
:data:`ADOPT_HEARTBEATS` such HEARTBEATs from one system and component with the same type, none
older than ``heartbeat_timeout_s``, while no other PX4 autopilot is heard (two at once: neither
is adopted, a warning says to set ``mavlink.target_system``). A stray HEARTBEAT of another
system (a rogue sysid 42 talking first) never becomes the vehicle. What is adopted without
``target_system`` is logged as a warning (a rogue that talks alone first would be adopted), and
once adopted, a HEARTBEAT of any other PX4 autopilot (:meth:`Adoption.rival`) is a conflict that
the mission refuses to fly through; with ``target_system`` set, other systems are only counted.
"""
from __future__ import annotations

import logging

from mission.mavlink.env import mavlink

log = logging.getLogger("mission.mavlink.link")

#: MAV_TYPEs of a vehicle (what PX4 flies or drives; the passenger UAV and a PX4 rover or boat
#: carrier share this link code): fixed wing 1, quadrotor 2, coaxial 3, helicopter 4, airship 7,
#: balloon 8, rocket 9, ground rover 10, surface boat 11, submarine 12, hexa 13, octo 14, tricopter
#: 15, flapping wing 16, kite 17, VTOLs 19-25, parafoil 28, dodeca 29, deca 35, generic multirotor
#: 43, quadruped 46, VTOL gyrodyne 47. Anything else (a GCS 6, an onboard controller 18, a gimbal,
#: a camera, an ADS-B receiver...) is never adopted as the vehicle.
VEHICLE_TYPES = frozenset({1, 2, 3, 4, *range(7, 18), *range(19, 26), 28, 29, 35, 43, 46, 47})
#: Consistent HEARTBEATs needed to adopt a vehicle when ``target_system`` is not configured.
ADOPT_HEARTBEATS = 3


class Adoption:
    """Decides, HEARTBEAT by HEARTBEAT, when an autopilot becomes the vehicle (module docstring).

    :meth:`offer` returns True for the HEARTBEAT that adopts; :attr:`foreign_heartbeats` then
    counts the HEARTBEATs heard from other systems before adoption (``rejected_foreign``).
    """

    def __init__(self, target_system: int | None, target_component: int, heartbeat_timeout_s: float) -> None:
        self.target_system, self.target_component = target_system, target_component
        self.heartbeat_timeout_s = heartbeat_timeout_s
        self.foreign_heartbeats = 0
        # unidentified PX4 autopilots heard: (sysid, compid) -> [heartbeats, last rx [s], MAV_TYPE]
        self._candidates: dict[tuple[int, int], list[int | float]] = {}
        self._heard: dict[tuple[int, int], int] = {}  # PX4 HEARTBEATs heard before adoption, per source
        self._ambiguous_warned = False
        self._ignored_autopilots: set[tuple[int, int]] = set()

    def is_candidate(self, mav_type: int, autopilot: int, source: tuple[int, int]) -> bool:
        """Could this HEARTBEAT be the PX4 autopilot we are to fly?"""
        if mav_type not in VEHICLE_TYPES:
            return False
        if self.target_system is not None and source[0] != self.target_system:
            return False
        if self.target_component and source[1] != self.target_component:
            return False
        if autopilot != mavlink.MAV_AUTOPILOT_PX4:
            if source not in self._ignored_autopilots:
                self._ignored_autopilots.add(source)
                log.warning("ignoring non-PX4 autopilot %d at sysid %d compid %d", autopilot, *source)
            return False
        return True

    def offer(self, mav_type: int, autopilot: int, source: tuple[int, int], t_rx: float, address: object = None) -> bool:
        """A HEARTBEAT from ``source`` (at ``address``, for the log) received at ``t_rx`` [s]:
        does it adopt ``source`` now?"""
        if not self.is_candidate(mav_type, autopilot, source):
            return False
        if self.target_system is not None:
            log.info("vehicle adopted (mavlink.target_system): PX4 autopilot sysid %d compid %d, MAV_TYPE %d",
                     source[0], source[1], mav_type)
            return True
        if len(self._heard) < 64 or source in self._heard:
            self._heard[source] = self._heard.get(source, 0) + 1
        fresh = {k: c for k, c in self._candidates.items() if t_rx - c[1] <= self.heartbeat_timeout_s}
        cand = fresh.get(source)
        if cand is None or cand[2] != mav_type:
            cand = [0, t_rx, mav_type]
        cand[0], cand[1] = cand[0] + 1, t_rx
        fresh[source] = cand
        self._candidates = fresh
        if cand[0] < ADOPT_HEARTBEATS:
            return False
        others = sorted(k for k in fresh if k != source)
        if others:
            if not self._ambiguous_warned:
                self._ambiguous_warned = True
                log.warning("several PX4 autopilots heard (%s and %s): adopting none while both talk; "
                            "set mavlink.target_system", source, ", ".join(map(str, others)))
            return False
        self._candidates.clear()
        self.foreign_heartbeats = sum(n for k, n in self._heard.items() if k[0] != source[0])
        log.warning("vehicle adopted after %d consistent HEARTBEATs: PX4 autopilot sysid %d compid %d, MAV_TYPE %d, "
                    "at %s, WITHOUT mavlink.target_system: the first PX4 that talks alone is flown; any other PX4 "
                    "autopilot heard from now on aborts the mission; set mavlink.target_system for real flights",
                    cand[0], source[0], source[1], mav_type, address if address is not None else "the link")
        return True

    def rival(self, mav_type: int, autopilot: int, source: tuple[int, int], vehicle: tuple[int, int]) -> str | None:
        """A HEARTBEAT from ``source`` after ``vehicle`` was adopted: why it makes the vehicle
        ambiguous (another PX4 autopilot of a vehicle type, ``target_system`` unset), or None."""
        if self.target_system is not None or source == vehicle or not self.is_candidate(mav_type, autopilot, source):
            return None
        text = (f"a second PX4 autopilot (sysid {source[0]} compid {source[1]}, MAV_TYPE {mav_type}) talks beside the "
                f"adopted vehicle (sysid {vehicle[0]} compid {vehicle[1]}) and mavlink.target_system is unset: which "
                f"one to fly is unknown; set mavlink.target_system to the vehicle's MAV_SYS_ID")
        log.error("%s", text)
        return text
