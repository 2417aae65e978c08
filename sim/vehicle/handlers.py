"""What the mock vehicle does with the messages it receives: commands (with PX4's ACKs and
checks), setpoints, the parameter protocol, HEARTBEATs and TIMESYNC.

:class:`MessageHandlers` is the receiving half of :class:`sim.vehicle.mock.MockVehicle`: it reads and
changes that vehicle's state (commander, parameters, streams, counters) under the vehicle's lock,
at the vehicle's simulated time, and answers through the vehicle's outbound path (its faults).
"""
from __future__ import annotations

import collections
import logging
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from mission.mavlink import px4
from mission.mavlink.env import mavlink
from sim.vehicle import telemetry as tel
from sim.vehicle.endpoints import VehicleLink
from sim.vehicle.params import UnknownParam
from sim.vehicle.protocol import int_param, mode_of_set_mode, param_value, setpoint_of

if TYPE_CHECKING:
    from sim.vehicle.mock import MockVehicle

log = logging.getLogger("sim.vehicle.mock")
INT32_MAX = 0x7FFFFFFF  # COMMAND_INT x / y: not given


class MessageHandlers:
    """Dispatch of received messages by type, and of commands by number (lock held by the caller)."""

    def __init__(self, vehicle: MockVehicle) -> None:
        self.v = vehicle
        opts = vehicle.options
        self._command_handlers: dict[int, Callable[[VehicleLink, list[float]], tuple[int, list[Any]]]] = {
            px4.MAV_CMD_DO_SET_MODE: self._cmd_set_mode,
            px4.MAV_CMD_COMPONENT_ARM_DISARM: self._cmd_arm_disarm,
            px4.MAV_CMD_NAV_TAKEOFF: self._cmd_takeoff,
            px4.MAV_CMD_NAV_LAND: lambda link, p: (self.v._commander.set_mode(self.v._t_s, "AUTO.LAND"), []),
            px4.MAV_CMD_NAV_RETURN_TO_LAUNCH: lambda link, p: (self.v._commander.set_mode(self.v._t_s, "AUTO.RTL"), []),
            mavlink.MAV_CMD_DO_SET_HOME: self._cmd_set_home,
            px4.MAV_CMD_REQUEST_MESSAGE: self._cmd_request_message,
            px4.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: lambda link, p: (px4.MAV_RESULT_ACCEPTED, [tel.autopilot_version(opts.sysid)]),
            px4.MAV_CMD_SET_MESSAGE_INTERVAL: self._cmd_set_message_interval,
            px4.MAV_CMD_GET_MESSAGE_INTERVAL: self._cmd_get_message_interval,
        }
        self._handlers: dict[str, Callable[[VehicleLink, Any], None]] = {
            "HEARTBEAT": self._on_heartbeat,
            "COMMAND_LONG": self._on_command_long,
            "COMMAND_INT": self._on_command_int,
            "SET_POSITION_TARGET_LOCAL_NED": self._on_setpoint,
            "PARAM_REQUEST_LIST": self._on_param_request_list,
            "PARAM_REQUEST_READ": self._on_param_request_read,
            "PARAM_SET": self._on_param_set,
            "TIMESYNC": self.timesync,
            "LANDING_TARGET": self._on_landing_target,
        }
        # the LANDING_TARGETs read as PX4's receiver reads them (simulated time [s], reading), newest last
        self.landing_targets: collections.deque[tuple[float, px4.LandingTargetReading]] = collections.deque(maxlen=100)

    def process(self, link: VehicleLink, data: bytes, address: tuple[str, int]) -> None:
        """One datagram that passed the inbound faults."""
        self.v._counters["rx_datagrams"] += 1
        messages, leftover = link.parse(data)
        if leftover:
            self.v._counters["rx_malformed"] += 1
        for msg in messages:
            self._dispatch(link, msg, address)
        self.v._io.send_statustexts()

    def _dispatch(self, link: VehicleLink, msg: Any, address: tuple[str, int]) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            unsigned = "signature" in str(getattr(msg, "reason", ""))
            self.v._counters["rx_unsigned_rejected" if unsigned else "rx_malformed"] += 1
            log.debug("rx %s from %s: %s", kind, address, getattr(msg, "reason", ""))
            return
        if kind.startswith("UNKNOWN_"):
            self.v._counters["rx_unknown_ids"] += 1
            return
        self.v._counters["rx_messages"] += 1
        link.latch(address)
        handler = self._handlers.get(kind)
        if handler is None:
            self.v._counters["rx_ignored"] += 1
            return
        try:
            handler(link, msg)
        except (ValueError, TypeError, OverflowError, AttributeError, UnicodeError) as exc:
            self.v._counters["rx_malformed"] += 1
            log.debug("rx %s rejected: %s", kind, exc)

    def _targets_me(self, msg: Any) -> bool:
        ok = (msg.target_system in (0, self.v.options.sysid)) and (msg.target_component in (0, self.v.options.compid))
        if not ok:
            self.v._counters["rx_wrong_target"] += 1
        return ok

    def _on_heartbeat(self, link: VehicleLink, msg: Any) -> None:
        link.last_peer_heartbeat_s = self.v._t_s

    def _on_command_long(self, link: VehicleLink, msg: Any) -> None:
        if self._targets_me(msg):
            params = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7]
            self._command(link, msg, [float(p) for p in params])

    def _on_command_int(self, link: VehicleLink, msg: Any) -> None:
        """As PX4's receiver: x and y are degrees x 1e7 (INT32_MAX: not given, NaN), z as it is."""
        if self._targets_me(msg):
            lat, lon = (math.nan if v == INT32_MAX else v * 1e-7 for v in (msg.x, msg.y))
            params = [msg.param1, msg.param2, msg.param3, msg.param4, lat, lon, msg.z]
            self._command(link, msg, [float(p) for p in params])

    def _command(self, link: VehicleLink, msg: Any, params: list[float]) -> None:
        """Run a command and ACK it to its sender (after which any reply messages follow)."""
        self.v._counters["commands"] += 1
        handler = self._command_handlers.get(msg.command)
        result, replies = handler(link, params) if handler else (px4.MAV_RESULT_UNSUPPORTED, [])
        header = msg.get_header()
        ack = mavlink.MAVLink_command_ack_message(msg.command, result, 0, 0, header.srcSystem, header.srcComponent)
        self.v._io.send(link, ack)
        for reply in replies:
            self.v._io.send(link, reply)
        log.debug("command %d %s -> result %d", msg.command, params, result)

    def _cmd_set_mode(self, link: VehicleLink, p: list[float]) -> tuple[int, list[Any]]:
        name = mode_of_set_mode(p)
        if name is None:
            return px4.MAV_RESULT_UNSUPPORTED, []
        result = self.v._commander.set_mode(self.v._t_s, name)
        log.info("DO_SET_MODE %s -> %d", name, result)
        return result, []

    def _cmd_arm_disarm(self, link: VehicleLink, p: list[float]) -> tuple[int, list[Any]]:
        arm, force = int_param(p[0]), int_param(p[1]) == px4.ARM_FORCE_MAGIC
        if arm == 1:  # PX4 runs the checks for every external arm, forced or not (Commander.cpp)
            result = self.v._commander.arm(self.v._t_s)
        elif arm == 0:
            result = self.v._commander.disarm(self.v._t_s, force)
        else:
            result = px4.MAV_RESULT_DENIED
        log.info("%s%s -> %d", "ARM" if arm == 1 else "DISARM", " (forced)" if force else "", result)
        return result, []

    def _cmd_takeoff(self, link: VehicleLink, p: list[float]) -> tuple[int, list[Any]]:
        if self.v.options.frame == "rover":
            return px4.MAV_RESULT_UNSUPPORTED, []
        home_amsl_m = self.v.options.home[2] - self.v._commander.home_ned_m[2]
        altitude_m = p[6] - home_amsl_m if math.isfinite(p[6]) else None
        return self.v._commander.takeoff(self.v._t_s, altitude_m), []

    def _cmd_set_home(self, link: VehicleLink, p: list[float]) -> tuple[int, list[Any]]:
        """DO_SET_HOME: param1 = 1 here, else param5/6/7 latitude, longitude [deg], altitude
        [m AMSL] through the EKF origin (PX4's projection). HOME_POSITION shows it at the stream's
        next message (PX4 SITL: up to 2 s later, at 0.5 Hz; nothing is sent at once)."""
        here = int_param(p[0]) == 1
        home = None if here else self.v._geo.to_local(p[4], p[5], p[6])
        result = self.v._commander.set_home(self.v._t_s, home)
        log.debug("DO_SET_HOME %s -> %d", "here" if here else tuple(round(c, 2) for c in home or ()), result)
        return result, []

    def _stream_of(self, link: VehicleLink, msg_id: int) -> tel.Stream | None:
        return self.v._schedule.of(link.name, msg_id)

    def _cmd_request_message(self, link: VehicleLink, p: list[float]) -> tuple[int, list[Any]]:
        msg_id = int_param(p[0])
        if msg_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return px4.MAV_RESULT_ACCEPTED, [tel.autopilot_version(self.v.options.sysid)]
        stream = self._stream_of(link, msg_id)
        if stream is None:
            return px4.MAV_RESULT_DENIED, []  # as PX4 when it cannot send the message
        msg = tel.build(stream.name, self.v._telemetry_state(), self.v._geo, self.v._noise)
        return (px4.MAV_RESULT_DENIED, []) if msg is None else (px4.MAV_RESULT_ACCEPTED, [msg])

    def _cmd_set_message_interval(self, link: VehicleLink, p: list[float]) -> tuple[int, list[Any]]:
        """PX4's rules (mavlink_receiver.cpp, and measured on SITL): FAILED for HEARTBEAT, for a
        message it cannot stream, or with param3, param4 or param7 (response target) set; interval
        < 0 stops the stream, 0 (or NaN) restores the default, > 0 sets it (delivered up to the
        stream's source rate). Only the link the command came on changes. DISTANCE_SENSOR with a
        rangefinder is accepted and changes nothing (every reading is sent, as PX4's stream sends each
        new sample at a rate asked at or above the sensor's)."""
        msg_id, interval_us = int_param(p[0]), p[1]
        stream = self._stream_of(link, msg_id)
        extras_set = any(math.isfinite(x) and int(x + 0.5) != 0 for x in (p[2], p[3], p[6]))
        if msg_id == mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR and self.v.options.rangefinder is not None and not extras_set:
            return px4.MAV_RESULT_ACCEPTED, []  # its rangefinder sends every reading whatever the interval
        if stream is None or msg_id == mavlink.MAVLINK_MSG_ID_HEARTBEAT or extras_set:
            return px4.MAV_RESULT_FAILED, []
        self.v._schedule.set_interval(stream, interval_us, self.v._t_s)
        return px4.MAV_RESULT_ACCEPTED, []

    def _cmd_get_message_interval(self, link: VehicleLink, p: list[float]) -> tuple[int, list[Any]]:
        """MESSAGE_INTERVAL of the stream on this link (PX4: 0 when it is not streamed), sent
        before the ACK as PX4 does."""
        msg_id = int_param(p[0])
        stream = self._stream_of(link, msg_id)
        self.v._io.send(link, mavlink.MAVLink_message_interval_message(msg_id, stream.interval_us() if stream else 0))
        return px4.MAV_RESULT_ACCEPTED, []

    def _on_setpoint(self, link: VehicleLink, msg: Any) -> None:
        if not self._targets_me(msg):
            return
        setpoint, reason = setpoint_of(msg, self.v._kin.yaw_rad)
        if setpoint is None:
            self.v._counters["setpoints_rejected"] += 1
            self.v._commander.reject_setpoint(self.v._t_s, reason)
            return
        self.v._counters["setpoints_accepted"] += 1
        self.v._commander.accept_setpoint(self.v._t_s, setpoint)

    def _on_landing_target(self, link: VehicleLink, msg: Any) -> None:
        """PX4's rule (``handle_message_landing_target``): position-valid in LOCAL_NED becomes the
        landing target's pose (accepted; PX4's precision landing may use it, OFFBOARD ignores it);
        position-valid in another frame is refused with PX4's critical STATUSTEXT; position_valid
        0 is an IR-LOCK report, which nothing reads on a vehicle without an IR-LOCK estimator (ignored)."""
        reading = px4.landing_target_reading(msg)
        self.landing_targets.append((self.v._t_s, reading))
        if reading.kind == "pose":
            self.v._counters["landing_targets_accepted"] += 1
            return
        self.v._counters["landing_targets_ignored"] += 1
        if reading.kind == "unsupported_frame":
            self.v._commander._say(f"Landing target: coordinate frame {reading.frame} unsupported", px4.MAV_SEVERITY_CRITICAL)

    def _on_param_request_list(self, link: VehicleLink, msg: Any) -> None:
        if self._targets_me(msg):
            for index in range(len(self.v.params)):
                self.v._io.send(link, param_value(self.v.params, self.v.params.name_at(index)))

    def _on_param_request_read(self, link: VehicleLink, msg: Any) -> None:
        if not self._targets_me(msg):
            return
        try:
            name = self.v.params.name_at(msg.param_index) if msg.param_index >= 0 else str(msg.param_id)
            self.v._io.send(link, param_value(self.v.params, name))
        except (UnknownParam, KeyError):
            self.v._counters["rx_ignored"] += 1

    def _on_param_set(self, link: VehicleLink, msg: Any) -> None:
        if not self._targets_me(msg):
            return
        try:
            self.v.params.set_from_wire(str(msg.param_id), msg.param_value, msg.param_type)
        except (UnknownParam, ValueError):
            self.v._counters["rx_ignored"] += 1
            return
        self.v._counters["params_set"] += 1
        log.info("PARAM_SET %s = %g", msg.param_id, self.v.params.get(str(msg.param_id)))
        self.v._io.send(link, param_value(self.v.params, str(msg.param_id)))

    def timesync(self, link: VehicleLink, msg: Any) -> None:
        """A TIMESYNC request (answered at simulated time), or a lockstep answer."""
        if msg.tc1 == 0:
            self.v._io.send(link, mavlink.MAVLink_timesync_message(int(self.v._t_s * 1e9), msg.ts1))
        elif self.v._lockstep is not None:
            self.v._lockstep.on_answer(link, msg)

