"""A scriptable fake PX4: a real pymavlink endpoint on a real socket, for tests and benches.

It streams HEARTBEAT and LOCAL_POSITION_NED like PX4's onboard link (faster, to keep tests
short), records every message it receives, and answers COMMAND_LONG through a replaceable
policy (``fake.on_command``), so a test can make the vehicle accept, reject with a STATUSTEXT
reason, stay silent, or double-ACK a mode change as PX4 of 2025 does. With ``rx_stamps`` it
also records the kernel's receive stamp of every datagram (the bench's end-to-end latency).

It is not a model of PX4 (no dynamics, no failsafes): that is :mod:`sim.vehicle.mock`'s job.
"""
from __future__ import annotations

import threading
import time
from typing import Any, Callable

from mission.mavlink import px4
from mission.mavlink.env import mavlink, mavutil
from sim.net import enable_rx_stamps, recv_stamped

CommandPolicy = Callable[["FakePx4", Any], None]


class FakePx4:
    """PX4-like endpoint (sysid/compid, HEARTBEAT, LOCAL_POSITION_NED, COMMAND_LONG answers).

    ``url`` defaults to ``udpout:127.0.0.1:<link_port>`` (the vehicle talks first, as PX4 SITL
    does towards 14540). Rates are wall-clock Hz; 0 stops that stream. It starts disarmed in
    Hold; set ``armed`` / ``custom_mode`` to script another state. ``rx_stamps`` (UDP only):
    keep ``(kernel receive stamp [ns, CLOCK_REALTIME], message)`` of every message in
    :attr:`stamped`.
    """

    def __init__(
        self,
        link_port: int | None = None,
        *,
        url: str | None = None,
        sysid: int = 1,
        compid: int = 1,
        autopilot: int = mavlink.MAV_AUTOPILOT_PX4,
        mav_type: int = mavlink.MAV_TYPE_QUADROTOR,
        heartbeat_hz: float = 20.0,
        position_hz: float = 50.0,
        position_ned_m: tuple[float, float, float] = (1.0, 2.0, -3.0),
        velocity_ned_m_s: tuple[float, float, float] = (0.1, 0.2, 0.3),
        signing_key: bytes | None = None,
        rx_stamps: bool = False,
    ) -> None:
        self.conn: Any = mavutil.mavlink_connection(
            url or f"udpout:127.0.0.1:{link_port}", source_system=sysid, source_component=compid
        )
        if signing_key is not None:
            self.conn.setup_signing(signing_key, sign_outgoing=True, allow_unsigned_callback=lambda _m, _i: True)
        self.rx_stamps = rx_stamps
        if rx_stamps:
            enable_rx_stamps(self.conn.port)
        self.autopilot, self.mav_type = autopilot, mav_type
        self.heartbeat_hz, self.position_hz = heartbeat_hz, position_hz
        self.position_ned_m, self.velocity_ned_m_s = position_ned_m, velocity_ned_m_s
        self.custom_mode = px4.custom_mode_of("AUTO.LOITER")
        self.armed = False
        self.on_command: CommandPolicy = FakePx4.obey
        self.stamped: list[tuple[int, Any]] = []
        self._received: list[Any] = []
        self._text_id = 0
        self._lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fake-px4", daemon=True)

    # ---------------------------------------------------------------- lifetime

    def __enter__(self) -> FakePx4:
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
        """Send raw bytes from the fake's own socket (garbage tests)."""
        with self._send_lock:
            self.conn.write(data)

    def heartbeat(self) -> None:
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0)
        status = mavlink.MAV_STATE_ACTIVE if self.armed else mavlink.MAV_STATE_STANDBY
        self.send(mavlink.MAVLink_heartbeat_message(self.mav_type, self.autopilot, base, self.custom_mode, status, 3))

    def local_position(self) -> None:
        (x, y, z), (vx, vy, vz) = self.position_ned_m, self.velocity_ned_m_s
        boot_ms = int(time.monotonic() * 1000) & 0xFFFFFFFF
        self.send(mavlink.MAVLink_local_position_ned_message(boot_ms, x, y, z, vx, vy, vz))

    def statustext(self, text: str, severity: int = 2, text_id: int = 0, chunk_seq: int = 0) -> None:
        self.send(mavlink.MAVLink_statustext_message(severity, text.encode(), text_id, chunk_seq))

    def long_statustext(self, text: str, severity: int = 2) -> None:
        """Send ``text`` in 50-character chunks with a fresh non-zero id, as PX4 does."""
        self._text_id = self._text_id % 65535 + 1
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
    def obey(fake: FakePx4, msg: Any) -> None:
        """Default policy: apply arm/disarm and mode changes, ACK everything ACCEPTED."""
        if msg.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            fake.armed = round(msg.param1) == 1
        elif msg.command == mavlink.MAV_CMD_DO_SET_MODE:
            fake.custom_mode = px4.encode_custom_mode(int(msg.param2), int(msg.param3))
        fake.ack(msg, mavlink.MAV_RESULT_ACCEPTED)

    @staticmethod
    def obey_and_beat(fake: FakePx4, msg: Any) -> None:
        """Policy: :meth:`obey`, then a HEARTBEAT at once (the new mode shows without waiting)."""
        FakePx4.obey(fake, msg)
        fake.heartbeat()

    @staticmethod
    def silent(fake: FakePx4, msg: Any) -> None:
        """Policy: never answer."""

    # ---------------------------------------------------------------- loop

    def _run(self) -> None:
        next_hb = next_pos = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            heartbeat_hz, position_hz = self.heartbeat_hz, self.position_hz  # once: a test may zero them meanwhile
            if heartbeat_hz and now >= next_hb:
                self.heartbeat()
                next_hb = now + 1.0 / heartbeat_hz
            if position_hz and now >= next_pos:
                self.local_position()
                next_pos = now + 1.0 / position_hz
            due = min(t for t, on in ((next_hb, heartbeat_hz), (next_pos, position_hz), (now + 0.05, True)) if on)
            if self.conn.select(min(max(due - time.monotonic(), 0.0), 0.05)):
                self._drain()

    def _drain(self) -> None:
        if self.rx_stamps:
            self._drain_stamped()
            return
        while True:
            msg = self.conn.recv_msg()
            if msg is None:
                return
            self._handle(msg)

    def _drain_stamped(self) -> None:
        """One datagram with its kernel stamp (``recv_msg`` would lose the stamp)."""
        try:
            data, stamp_ns, _ = recv_stamped(self.conn.port)
        except OSError:
            return
        try:
            messages = self.conn.mav.parse_buffer(data) or []
        except Exception:  # malformed: pymavlink raises on some; the fake only records
            return
        for msg in messages:
            with self._lock:
                self.stamped.append((stamp_ns, msg))
            self._handle(msg)

    def _handle(self, msg: Any) -> None:
        if msg.get_type() == "BAD_DATA":
            return
        with self._lock:
            self._received.append(msg)
        if msg.get_type() == "COMMAND_LONG":
            self.on_command(self, msg)
