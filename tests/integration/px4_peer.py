"""A PX4-like MAVLink peer for link tests: a real pymavlink endpoint on a real socket.

It streams HEARTBEAT and LOCAL_POSITION_NED like PX4's onboard link (faster, to keep tests
short), records every message it receives, and answers COMMAND_LONG through a replaceable
policy (``peer.on_command``), so a test can make the vehicle accept, reject with a STATUSTEXT
reason, stay silent, or double-ACK a mode change as PX4 of 2025 does. It is not a model of
PX4: that is ``sim/vehicle.py``'s job.
"""
from __future__ import annotations

import threading
import time
from typing import Any, Callable

from mission import px4
from mission.mavlink_env import mavlink, mavutil


class Px4Peer:
    """PX4-like endpoint (sysid/compid, HEARTBEAT, LOCAL_POSITION_NED, COMMAND_LONG answers).

    ``url`` defaults to ``udpout:127.0.0.1:<link_port>`` (the vehicle talks first, as PX4 SITL
    does towards 14540). Rates are wall-clock Hz.
    """

    def __init__(
        self,
        link_port: int | None = None,
        *,
        url: str | None = None,
        sysid: int = 1,
        compid: int = 1,
        autopilot: int = px4.MAV_AUTOPILOT_PX4,
        mav_type: int = px4.MAV_TYPE_QUADROTOR,
        heartbeat_hz: float = 20.0,
        position_hz: float = 50.0,
        position_ned_m: tuple[float, float, float] = (1.0, 2.0, -3.0),
        velocity_ned_m_s: tuple[float, float, float] = (0.1, 0.2, 0.3),
        signing_key: bytes | None = None,
    ) -> None:
        self.conn: Any = mavutil.mavlink_connection(
            url or f"udpout:127.0.0.1:{link_port}", source_system=sysid, source_component=compid
        )
        if signing_key is not None:
            self.conn.setup_signing(signing_key, sign_outgoing=True, allow_unsigned_callback=lambda _m, _i: True)
        self.autopilot, self.mav_type = autopilot, mav_type
        self.heartbeat_hz, self.position_hz = heartbeat_hz, position_hz
        self.position_ned_m, self.velocity_ned_m_s = position_ned_m, velocity_ned_m_s
        self.custom_mode = px4.custom_mode_of("AUTO.LOITER")
        self.armed = False
        self.on_command: Callable[[Px4Peer, Any], None] = Px4Peer.obey
        self._received: list[Any] = []
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="test-px4-peer", daemon=True)

    # ---------------------------------------------------------------- lifetime

    def __enter__(self) -> Px4Peer:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.conn.close()

    # ---------------------------------------------------------------- what it received

    def received(self, kind: str | None = None) -> list[Any]:
        with self._lock:
            return [m for m in self._received if kind is None or m.get_type() == kind]

    # ---------------------------------------------------------------- sending

    def send(self, msg: Any) -> None:
        with self._send_lock:
            self.conn.mav.send(msg)

    def send_raw(self, data: bytes) -> None:
        """Send raw bytes from the peer's own socket (garbage tests)."""
        with self._send_lock:
            self.conn.write(data)

    def heartbeat(self) -> None:
        base = px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (px4.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0)
        status = px4.MAV_STATE_ACTIVE if self.armed else px4.MAV_STATE_STANDBY
        self.send(mavlink.MAVLink_heartbeat_message(self.mav_type, self.autopilot, base, self.custom_mode, status, 3))

    def local_position(self) -> None:
        (x, y, z), (vx, vy, vz) = self.position_ned_m, self.velocity_ned_m_s
        boot_ms = int(time.monotonic() * 1000) & 0xFFFFFFFF
        self.send(mavlink.MAVLink_local_position_ned_message(boot_ms, x, y, z, vx, vy, vz))

    def statustext(self, text: str, severity: int = 2, text_id: int = 0, chunk_seq: int = 0) -> None:
        self.send(mavlink.MAVLink_statustext_message(severity, text.encode(), text_id, chunk_seq))

    def long_statustext(self, text: str, severity: int = 2) -> None:
        """Send ``text`` in 50-character chunks with a fresh non-zero id, as PX4 does."""
        self._text_id = getattr(self, "_text_id", 0) % 65535 + 1
        chunks = [text[i:i + 50] for i in range(0, len(text), 50)] or [""]
        if len(chunks[-1]) == 50:
            chunks.append("")  # a full last chunk is followed by an empty one that ends the text
        for seq, chunk in enumerate(chunks):
            self.statustext(chunk, severity, self._text_id, seq)

    def ack(self, command_msg: Any, result: int) -> None:
        self.send(mavlink.MAVLink_command_ack_message(
            command_msg.command, result, 0, 0, command_msg.get_srcSystem(), command_msg.get_srcComponent()
        ))

    # ---------------------------------------------------------------- command policies

    @staticmethod
    def obey(peer: Px4Peer, msg: Any) -> None:
        """Default policy: apply arm/disarm and mode changes, ACK everything ACCEPTED."""
        if msg.command == px4.MAV_CMD_COMPONENT_ARM_DISARM:
            peer.armed = round(msg.param1) == 1
        elif msg.command == px4.MAV_CMD_DO_SET_MODE:
            peer.custom_mode = px4.encode_custom_mode(int(msg.param2), int(msg.param3))
        peer.ack(msg, px4.MAV_RESULT_ACCEPTED)

    @staticmethod
    def silent(peer: Px4Peer, msg: Any) -> None:
        """Policy: never answer."""

    # ---------------------------------------------------------------- loop

    def _run(self) -> None:
        next_hb = next_pos = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            if self.heartbeat_hz and now >= next_hb:
                self.heartbeat()
                next_hb = now + 1.0 / self.heartbeat_hz
            if self.position_hz and now >= next_pos:
                self.local_position()
                next_pos = now + 1.0 / self.position_hz
            if self.conn.select(0.002):
                self._drain()

    def _drain(self) -> None:
        while True:
            msg = self.conn.recv_msg()
            if msg is None:
                return
            if msg.get_type() == "BAD_DATA":
                continue
            with self._lock:
                self._received.append(msg)
            if msg.get_type() == "COMMAND_LONG":
                self.on_command(self, msg)
