"""An in-process fake world for the mission loop: vehicle, carrier feed and status sink, no sockets.

In the spirit of the PX4 ROS 2 Interface Library's fake autopilot: the controller talks to it
through the same narrow interfaces (:mod:`mission.interfaces`) as to the MAVLink link and the Zenoh feed,
on a :class:`~mission.time.clock.ManualClock`, so a whole mission runs in a fraction of a second and
every test is deterministic. Physics are the simplest that fly: the vehicle's velocity is the last
setpoint while in OFFBOARD (zero otherwise), the carrier drives at ``carrier_speed_m_s`` towards
the target while the passenger's published phase is RIDING and stands otherwise (as the carrier
simulator does). Commands act at once, or are refused by a scripted policy.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mission.core.setpoint import Setpoint
from mission.mavlink import px4
from mission.bus.bridge import ReceivedCarrierState
from mission.time.clock import ManualClock
from mission.errors import CommandRejected, LinkTimeout
from mission.mavlink.link import VehicleState
from mission.mavlink.session import LinkCounters
from mission.bus.wire import CarrierState, GeoOrigin, PassengerStatus
from mission.phases.measurements import RelativePosition
from mission.phases.phase import Duty


POSITION_GAIN_PER_S = 0.95  # PX4's MPC_XY_P: the fake's position loop on full setpoints [1/s]


@dataclass
class FakeWorld:
    """Implements :class:`~mission.interfaces.Vehicle` and :class:`~mission.interfaces.StatusSink`, and
    :class:`~mission.interfaces.CarrierSource` as :attr:`feed`; lists what the controller did."""

    clock: ManualClock
    target_ned_m: np.ndarray
    carrier_speed_m_s: float = 2.0
    vehicle_ned_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    carrier_ned_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    armed: bool = False
    mode: str = "AUTO.LOITER"
    refuse: dict[str, str] = field(default_factory=dict)  # command name -> the vehicle's reason
    heartbeat_until_s: float = math.inf  # the vehicle falls silent after this [s]
    carrier_until_s: float = math.inf  # the carrier falls silent after this [s]
    disarmed_at_s: float = math.inf  # someone else disarms the vehicle at this time [s] (it falls, motors off)
    setpoints: list[tuple[float, np.ndarray]] = field(default_factory=list)
    commands: list[tuple[float, str]] = field(default_factory=list)
    statuses: list[PassengerStatus] = field(default_factory=list)
    origin_given: GeoOrigin | None = None
    intervals: list[tuple[int, float]] = field(default_factory=list)  # SET_MESSAGE_INTERVAL asked (id, Hz)
    landing_targets: list[tuple[float, Any]] = field(default_factory=list)  # LANDING_TARGETs sent (t [s], target)
    recovery_velocity_ned_m_s: np.ndarray = field(default_factory=lambda: np.zeros(3))  # the carrier's recovery course
    targets: list[list[float]] | None = None  # several targets: the carrier drives at the status's leg's
    reposition_m: float = 10.5  # REPOSITION: the carrier drives out until this far from the leg's target [m]
    carrier_accel_m_s2: float = math.inf  # the carrier's acceleration limit [m/s^2] (inf: instant)
    battery_pct: float | None = None  # remaining at t = 0 [%] (None: not reported) ...
    drain_pct_s: float = 0.0  # ... falling this fast while armed [%/s]
    homes: list[tuple[float, np.ndarray]] = field(default_factory=list)  # DO_SET_HOME asked (t [s], NED [m])
    params: dict[str, float] = field(default_factory=lambda: {"COM_OBL_RC_ACT": 0.0, "BAT_CRIT_THR": 0.07})
    param_sets: list[tuple[float, str, float]] = field(default_factory=list)  # (t [s], name, value) set

    def __post_init__(self) -> None:
        self._v_p = np.zeros(3)
        self._v_c = np.zeros(3)
        self._t = self.clock.now()
        self._carrier_rx_s = self._t
        self._seq = 0
        self._last_status_s = self._t

    # ------------------------------------------------------------------ the world
    def _advance(self) -> float:
        now = self.clock.now()
        dt = now - self._t
        if dt > 0:
            self.vehicle_ned_m = self.vehicle_ned_m + self._v_p * dt
            self.carrier_ned_m = self.carrier_ned_m + self._v_c * dt
            self._t = now
        return now

    # ------------------------------------------------------------------ Vehicle
    @property
    def state(self) -> VehicleState:
        now = self._advance()
        beat = min(now, self.heartbeat_until_s)
        if now >= self.disarmed_at_s:
            self.armed = False
        return VehicleState(
            t_s=now, system_id=1, component_id=1, position_ned_m=self.vehicle_ned_m.copy(),
            velocity_ned_m_s=self._v_p.copy(), position_rx_s=beat, heartbeat_rx_s=beat, armed=self.armed,
            mode=self.mode, custom_mode=px4.custom_mode_of(self.mode), base_mode=px4.base_mode_of(self.mode, self.armed),
            system_status=px4.MAV_STATE_ACTIVE if self.armed else px4.MAV_STATE_STANDBY, landed_state=None,
            position_valid=True, origin=None, last_statustext="", battery_pct=self._battery(now),
            believed_armed=self.armed)

    def _battery(self, now: float) -> float | None:
        if self.battery_pct is None:
            return None
        return max(self.battery_pct - self.drain_pct_s * now, 0.0)

    def send(self, setpoint: Setpoint) -> None:
        """The vehicle flies the setpoint's velocity while in OFFBOARD; a full setpoint adds a
        position loop as PX4's (``POSITION_GAIN_PER_S`` x the position error)."""
        now = self._advance()
        velocity = np.array(setpoint.velocity_ned_m_s, dtype=float)
        self.setpoints.append((now, velocity))
        if setpoint.position_ned_m is not None:
            velocity = velocity + POSITION_GAIN_PER_S * (setpoint.position_ned_m - self.vehicle_ned_m)
        self._v_p = velocity.copy() if self.mode == "OFFBOARD" else np.zeros(3)

    def send_landing_target(self, target: Any) -> None:
        """Kept, with the time it was sent, in ``landing_targets``."""
        self.landing_targets.append((self._advance(), target))

    def set_message_interval(self, message_id: int, rate_hz: float) -> None:
        self.intervals.append((message_id, rate_hz))

    def message_rate_hz(self) -> float:
        return 0.0

    def _command(self, name: str) -> None:
        self._advance()
        self.commands.append((self.clock.now(), name))
        if name in self.refuse:
            command = px4.MAV_CMD_COMPONENT_ARM_DISARM if name == "arm" else px4.MAV_CMD_DO_SET_MODE
            raise CommandRejected(command, px4.MAV_RESULT_DENIED, self.refuse[name])

    def arm(self) -> None:
        self._command("arm")
        self.armed = True

    def set_mode(self, mode: str) -> None:
        self._command(mode)
        self.mode = mode
        if mode != "OFFBOARD":
            self._v_p = np.zeros(3)

    def hold(self) -> None:
        self.set_mode("AUTO.LOITER")

    def disarm(self) -> None:
        self._command("disarm")
        self.armed = False

    def land(self) -> None:
        self.set_mode("AUTO.LAND")

    def set_home(self, home_ned_m: Any) -> int:
        self.homes.append((self._advance(), np.array(home_ned_m, dtype=float)))
        return px4.MAV_RESULT_ACCEPTED

    def get_param(self, name: str) -> float:
        if name not in self.params:
            raise LinkTimeout(f"no PARAM_VALUE {name}")
        return self.params[name]

    def set_param(self, name: str, value: float) -> float:
        self.param_sets.append((self._advance(), name, float(value)))
        self.params[name] = float(value)
        return float(value)

    def signing_problem(self) -> str | None:
        return None

    def identity_problem(self) -> str | None:
        return None

    @property
    def counters(self) -> LinkCounters:
        return LinkCounters()

    @property
    def feed(self) -> FakeFeed:
        """The world as a :class:`~mission.interfaces.CarrierSource`."""
        return FakeFeed(self)

    # ------------------------------------------------------------------ CarrierSource (through FakeFeed)
    def latest(self) -> ReceivedCarrierState | None:
        now = self._advance()
        if now <= self.carrier_until_s:
            self._seq += 1
            self._carrier_rx_s = now
        state = CarrierState(stamp_s=self._carrier_rx_s, seq=self._seq, frame="local_ned",
                             position=self.carrier_ned_m.copy(), velocity_ned_m_s=self._v_c.copy())
        return ReceivedCarrierState(value=state, key="fake/carrier", rx_time_s=self._carrier_rx_s,
                                    age_s=now - self._carrier_rx_s, stale=False, age_bound_s=0.0)  # one clock

    @property
    def alive(self) -> bool | None:
        return self.clock.now() <= self.carrier_until_s

    def alive_over_interval(self) -> bool | None:
        return self.alive  # the fake's carrier goes once, for good

    def set_origin(self, origin: GeoOrigin | None) -> None:
        self.origin_given = origin

    # ------------------------------------------------------------------ StatusSink
    def publish(self, status: PassengerStatus) -> None:
        self._advance()
        self.statuses.append(status)
        live = self.clock.now() <= self.carrier_until_s
        target = np.asarray(self.targets[status.leg] if self.targets is not None else self.target_ned_m, dtype=float)
        e = target - self.carrier_ned_m
        e[2] = 0.0
        distance = float(np.linalg.norm(e))
        if status.phase.duty is Duty.CARRY and live:
            wanted = e / distance * self.carrier_speed_m_s
        elif status.phase.duty is Duty.REPOSITION and live and distance < self.reposition_m:
            wanted = -e / distance * self.carrier_speed_m_s
        elif status.phase.duty is Duty.RECOVER and live:
            wanted = np.asarray(self.recovery_velocity_ned_m_s, dtype=float)
        else:
            wanted = np.zeros(3)
        step = wanted - self._v_c  # the carrier's velocity changes at most carrier_accel_m_s2
        cap = self.carrier_accel_m_s2 * max(self.clock.now() - self._last_status_s, 0.0)
        size = float(np.linalg.norm(step))
        self._v_c = self._v_c + (step * (cap / size) if size > cap else step)
        self._last_status_s = self.clock.now()




class TrueMarker:
    """A marker feed that sees the dock point from the world's vehicle exactly: captured now, its
    stated sigma 2 cm (``dock_offset`` [m] NED from the carrier)."""

    def __init__(self, world: FakeWorld, dock_offset: np.ndarray) -> None:
        self.world, self.dock_offset = world, dock_offset

    def poll(self, t_s: float) -> list[RelativePosition]:
        offset = self.world.carrier_ned_m + self.dock_offset - self.world.vehicle_ned_m
        return [RelativePosition(capture_t_s=t_s, offset_ned_m=offset, sigma_m=0.02)]

    def close(self) -> None:
        pass


@dataclass
class FakeFeed:
    """The fake world's carrier as the controller's :class:`~mission.interfaces.CarrierSource`."""

    world: FakeWorld

    def latest(self) -> ReceivedCarrierState | None:
        return self.world.latest()

    @property
    def alive(self) -> bool | None:
        return self.world.alive

    def alive_over_interval(self) -> bool | None:
        return self.world.alive_over_interval()

    def set_origin(self, origin: GeoOrigin | None) -> None:
        self.world.set_origin(origin)

    @property
    def counters(self) -> dict[str, Any]:
        return {"received": self.world._seq, "accepted": self.world._seq, "dropped": {}}
