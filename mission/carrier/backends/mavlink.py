"""``carrier.backend = "mavlink"``: a PX4 rover or boat as the carrier, through the passenger's
own link code (:class:`mission.mavlink.link.VehicleLink`: identification, ACKed commands confirmed by
HEARTBEAT, velocity setpoints in LOCAL_NED, signing).

State: LOCAL_POSITION_NED (position, velocity) and ATTITUDE (yaw), moved into the shared frame by
``carrier.mavlink.offset_ned_m`` [m], or, with ``carrier.mavlink.shared_origin`` (lat, lon, alt),
by the vehicle's own EKF origin (GPS_GLOBAL_ORIGIN) projected into the shared frame: two PX4s
whose EKF origins differ still agree on where the carrier is.

Control (a small state machine; the controller streams a setpoint every tick from the start,
zero until it wants motion, as PX4 needs before and during OFFBOARD)::

    no vehicle / HEARTBEAT lost / no valid position ----------------> fault: stop
    engage() asked, setpoints streamed >= prestream_s, not armed ----> arm (worker thread)
    armed, not OFFBOARD, never engaged -----------------------------> set OFFBOARD
    armed and OFFBOARD ---------------------------------------------> in control (engaged)
    engaged, then a mode other than OFFBOARD -----------------------> pilot took over: fault for
                                                                       good, never re-taken
    park() (the carrier is done: separated, parked under a passenger come home, or the passenger
        aborted), once its speed is below PARK_SPEED_M_S ---------> Hold (AUTO.LOITER): PX4 holds
                                                                       position where it stopped
    parked, then engage() (the passenger rides again: the next target) -> not engaged: set OFFBOARD
                                                                       again (Hold is ours, not a pilot's)

A zero velocity setpoint does not stop a PX4 rover well (its bearing atan2(0, 0) = 0 steers it
north while it brakes): "stop" is a tiny speed along its own heading while in OFFBOARD until it is
at rest (``carrier.mavlink.stand_speed_m_s``), then, with ``carrier.mavlink.stand = "position"``, a
position setpoint at the point where it came to rest, still in OFFBOARD, which PX4's rover position
control holds (``AckermannOffboardMode.cpp``: a position setpoint becomes PX4's own rover position
setpoint); the first command that is not a stop drives again (velocity setpoints). On the 1 mm/s
alone PX4's SIH rover crept or drifted 1.9-2.2 m in 70-80 s (bench/px4_rover_stand.py). Hold only
once the carrier is done and at rest, since PX4's Ackermann Hold drives back to the point where
Hold began (docs/carrier.md).

The vehicle is armed only when the carrier first has to move (the passenger rides), so a
carrier waiting for its passenger is not armed for nothing. On close it asks for Hold.
"""
from __future__ import annotations

import logging
import math

import numpy as np

from mission.flight_mode import FlightMode
from mission.carrier.backends import OwnState
from mission.carrier.tracking import Tracked, own_speed_m_s
from mission.core.setpoint import Setpoint
from mission.time.clock import Clock, Downstream
from mission.mavlink.lockstep import MavlinkRelay
from mission.config.schema import Config
from mission.mavlink.requests import CommandWorker
from mission.errors import LinkError
from mission.mavlink.link import VehicleLink
from mission.mavlink.telemetry import VehicleState
from mission.mavlink.env import read_signing_key
from mission.bus.wire import GeoOrigin, geodetic_to_ned

log = logging.getLogger(__name__)

STOP_SPEED_M_S = 1e-3  # [m/s] "stop" to a PX4 rover: this speed along its own heading (see command)
PARK_SPEED_M_S = 0.2  # [m/s] below this the stopped carrier is handed to PX4's Hold


def open_backend(cfg: Config, clock: Clock, session: object) -> MavlinkCarrier:
    """The PX4 vehicle of ``cfg.carrier.mavlink``, its link opened (``session`` unused)."""
    return MavlinkCarrier(cfg, clock)


def describe(cfg: Config) -> str:
    m = cfg.carrier.mavlink
    return f"PX4 vehicle on {m.url} (sysid {m.target_system or 'first PX4 heard'})"


def own_state_of(st: VehicleState, offset: np.ndarray | None, position_timeout_s: float) -> OwnState | None:
    """The carrier's own state from the link's ``st``: its local position moved by ``offset`` [m]
    into the shared frame, at the time the vehicle took the sample (its ``time_boot_ms`` on the
    link clock, ``position_t_s``; the receive time when that is not known). None without a
    position, a velocity or an ``offset``, or while the position is fresh (age <=
    ``position_timeout_s`` [s]) but unusable (non-finite, or the estimator says unhealthy).

    The sample time, not the receive time: a carrier process stalled 0.3-0.4 s read the samples
    that had waited in its socket, each stamped as new, and published a rover 0.5-0.7 m behind
    where it was as a fresh state; the riding passenger, which moves the dock point on by the
    state's age, then saw it leap forward, 0.30 -> 0.47 m off the dock in one tick
    (docs/recovery.md, "On real PX4")."""
    if st.position_ned_m is None or st.velocity_ned_m_s is None or st.position_rx_s is None or offset is None:
        return None
    if not st.position_valid and st.position_age_s <= position_timeout_s:
        return None  # fresh but unusable (non-finite, or the estimator says unhealthy)
    t_s = st.position_t_s if st.position_t_s is not None else st.position_rx_s
    return OwnState(t_s, st.position_ned_m + offset, np.array(st.velocity_ned_m_s), st.yaw_rad)


class MavlinkCarrier:
    """The carrier vehicle behind ``cfg.carrier.mavlink`` (the link is opened here)."""

    name = "mavlink"
    brakes_itself = True

    def __init__(self, cfg: Config, clock: Clock) -> None:
        m = cfg.carrier.mavlink
        self.clock, self.kind = clock, cfg.carrier.kinematics
        key = read_signing_key(m.signing_key_file) if m.signing_key_file else None
        source = m.source_system or m.target_system or 1
        self.link = VehicleLink(m.url, clock, target_system=m.target_system, source_system=source,
                                source_component=m.source_component, signing_key=key,
                                heartbeat_timeout_s=m.heartbeat_timeout_s, position_timeout_s=cfg.carrier.state_timeout_s)
        self.link.open()
        self.prestream_s = m.prestream_s
        self._offset = np.array(m.offset_ned_m, dtype=float)
        self._shared_origin = GeoOrigin(*m.shared_origin) if m.shared_origin else None
        self._origin_offset: np.ndarray | None = None
        self._worker: CommandWorker | None = None
        self._streaming_since: float | None = None
        self._want_control = False
        self._engaged = False
        self._override: str | None = None
        self._parked = False
        self._stand = m.stand
        self._stand_speed_m_s = m.stand_speed_m_s
        self.stand_at: np.ndarray | None = None  # [m] (3,) in the vehicle's own local NED: where it is held at rest
        self.send_errors = 0

    # ------------------------------------------------------------------ state
    def _frame_offset(self, origin: tuple[float, float, float] | None) -> np.ndarray | None:
        if self._shared_origin is None:
            return self._offset
        if self._origin_offset is None and origin is not None:
            self._origin_offset = geodetic_to_ned(*origin, self._shared_origin)
            log.info("carrier EKF origin %s is %s m (NED) from the shared origin", origin,
                     np.round(self._origin_offset, 3).tolist())
        return self._origin_offset

    def own_state(self) -> OwnState | None:
        st = self.link.state
        return own_state_of(st, self._frame_offset(st.origin), self.link.position_timeout_s)

    # ------------------------------------------------------------------ control
    def engage(self) -> None:
        """The carrier has to move: take control (arm, OFFBOARD) when the rules allow; a vehicle we
        parked in Hold is taken back (a Hold a pilot chose is an override, never taken back)."""
        self._want_control = True
        if self._parked:
            st = self.link.state
            if st.armed and st.mode not in (FlightMode.HOLD, FlightMode.OFFBOARD):  # moved out of our Hold
                self._override = f"pilot took over (mode {st.mode}) while parked; not commanding the carrier again"
                log.warning("carrier vehicle: %s", self._override)
            elif st.mode == FlightMode.HOLD:
                log.info("carrier vehicle: driving again, leaving the Hold we asked for")
                self._engaged = False  # OFFBOARD is asked again, as at the start
            self.stand_at = None  # Hold held it at its own point: a new rest point is taken
            self._parked = False

    def park(self) -> None:
        """The carrier is done (separated and stopping, or the passenger aborted): once it is at
        rest, ask for Hold (once, if we have control)."""
        if self._parked or not self._engaged:
            return
        st = self.link.state
        v = st.velocity_ned_m_s
        rolling = v is None or math.hypot(float(v[0]), float(v[1])) >= PARK_SPEED_M_S
        if st.armed and st.mode == FlightMode.OFFBOARD and not rolling:
            self._parked = True
            log.info("carrier vehicle: stopped for good, asking for Hold")
            self._ensure_worker().submit("hold")

    def control_fault(self) -> str | None:
        st = self.link.state
        if st.system_id is None:
            return "waiting for the vehicle's HEARTBEAT"
        if not self.link.vehicle_alive():
            return f"vehicle lost: no HEARTBEAT for {st.heartbeat_age_s:.1f} s"
        if self._override:
            return self._override
        if self._parked:
            return f"parked (mode {st.mode or '-'}): the carrier's part is done"
        if self._shared_origin is not None and self._origin_offset is None:
            return "waiting for the vehicle's EKF origin (GPS_GLOBAL_ORIGIN)"
        if not st.position_valid:
            return "no valid position estimate"
        if self._engaged and st.armed and st.mode != FlightMode.OFFBOARD:
            self._override = f"pilot took over (mode {st.mode}); not commanding the carrier again"
            log.warning("carrier vehicle: %s", self._override)
            return self._override
        if st.armed and st.mode == FlightMode.OFFBOARD:
            if not self._engaged:
                log.info("carrier vehicle armed and in OFFBOARD")
            self._engaged = True
            return None
        if not self._want_control:
            return "waiting for the passenger (not armed)"
        now = self.clock.now()
        if self._streaming_since is None or now - self._streaming_since < self.prestream_s:
            return "streaming setpoints before OFFBOARD"
        worker = self._ensure_worker()
        for request in ("arm", "offboard"):
            if request in worker.failed:
                return f"vehicle refused {request}: {worker.failed[request]}"
        worker.submit("arm" if not st.armed else "offboard")
        return "arming" if not st.armed else "switching to OFFBOARD"

    def _ensure_worker(self) -> CommandWorker:
        if self._worker is None:
            self._worker = CommandWorker(self.link, self.clock)
        return self._worker

    def advance(self, dt_s: float) -> None:
        pass

    def command(self, cmd: Tracked) -> None:
        if self.link.vehicle_id is None:
            return
        v = np.zeros(3)
        n = min(2, cmd.setpoint_ned_m_s.shape[0])
        v[:n] = cmd.setpoint_ned_m_s[:n]  # a ground or surface vehicle: no vertical command
        stop = math.hypot(v[0], v[1]) < STOP_SPEED_M_S
        if not stop:
            self.stand_at = None
        setpoint = self._stand_setpoint() if stop and self._stand == "position" else None
        yaw = self.link.state.yaw_rad
        if setpoint is None and self.kind != "holonomic" and stop and yaw is not None:
            # PX4's rover steers to atan2(v): a zero setpoint would turn it north while it brakes.
            v[0], v[1] = STOP_SPEED_M_S * math.cos(yaw), STOP_SPEED_M_S * math.sin(yaw)
        try:
            self.link.send(setpoint or Setpoint.velocity_only(v))
        except LinkError as exc:
            self.send_errors += 1
            if self.send_errors == 1:
                log.warning("carrier setpoint not sent: %s", exc)
            return
        if self._streaming_since is None:
            self._streaming_since = self.clock.now()

    def _stand_setpoint(self) -> Setpoint | None:
        """A stopped vehicle at rest: a position setpoint at the point where it came to rest (its own
        local NED, zero velocity and acceleration); None while it still rolls (or has no estimate)."""
        if self.stand_at is None:
            st = self.link.state
            pos, vel = st.position_ned_m, st.velocity_ned_m_s
            if pos is None or vel is None or not st.position_valid:
                return None
            if own_speed_m_s(vel, st.yaw_rad, self.kind) >= self._stand_speed_m_s:
                return None
            self.stand_at = np.array(pos, dtype=float)
            log.info("carrier vehicle: at rest, held at %s m (its local NED)", np.round(self.stand_at, 2).tolist())
        return Setpoint.triple(self.stand_at, np.zeros(3), np.zeros(3))

    def lockstep_relay(self, session: object) -> Downstream:
        """In lockstep, a simulated PX4 (``mock-vehicle --lockstep``) steps with the carrier
        through its barriers on this link."""
        return MavlinkRelay(self.link)

    def close(self) -> None:
        """Ask for Hold if we had control (best effort), stop the worker, close the link. Idempotent."""
        if not self.link.is_open:
            return
        try:
            st = self.link.state
            if self._engaged and not self._parked and st.armed and st.mode == FlightMode.OFFBOARD and self.link.vehicle_alive():
                self.link.hold(timeout_s=0.3, retries=1, confirm_timeout_s=1.0)
        except LinkError as exc:
            log.warning("carrier vehicle: Hold on exit not confirmed: %s", exc)
        finally:
            if self._worker is not None:
                self._worker.close()
                self._worker = None
            self.link.close()
