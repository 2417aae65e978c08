"""A live Foxglove viewer for tests and benches: a WebSocket client of the Foxglove protocol.

It speaks what the Foxglove app speaks to a foxglove-sdk server: subprotocol ``foxglove.sdk.v1``
(the SDK's name for ``foxglove.websocket.v1``, which it offers too; same messages), JSON
``serverInfo`` / ``advertise`` from the server, ``subscribe`` from the client, and binary
message data (opcode 1, subscription id u32, log time u64 [ns], payload), little-endian. It
subscribes to every channel advertised (or to ``topics``) and keeps what arrives.
"""
from __future__ import annotations

import base64
import json
import struct
import threading
import time
from typing import Any

SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")
MESSAGE_DATA = 0x01


class LiveViewer:
    """Connects to ``url`` (retrying until ``connect_timeout_s`` [s] wall), then receives on a thread.

    ``channels``: advertised channels by id; ``received``: topic -> [(log time [ns], payload,
    wall time of receipt [s])]. :meth:`close` disconnects."""

    def __init__(self, url: str, topics: set[str] | None = None, connect_timeout_s: float = 30.0) -> None:
        from websockets.sync.client import connect
        from websockets.typing import Subprotocol

        deadline = time.monotonic() + connect_timeout_s
        while True:
            try:
                # entered as ``with connect(...)`` would (websockets >= 17.1 warns about a bare connect);
                # no keepalive pings: a loaded test machine must not time the viewer out
                self.ws = connect(url, subprotocols=[Subprotocol(p) for p in SUBPROTOCOLS], open_timeout=5.0,
                                  max_size=None, ping_interval=None).__enter__()
                break
            except (OSError, TimeoutError):
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)
        self.subprotocol = self.ws.subprotocol
        self.topics = topics
        self.server_info: dict[str, Any] | None = None
        self.channels: dict[int, dict[str, Any]] = {}
        self.received: dict[str, list[tuple[int, bytes, float]]] = {}
        self._subscriptions: dict[int, str] = {}
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, name="foxglove-viewer", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from websockets.exceptions import ConnectionClosed

        try:
            for frame in self.ws:
                if isinstance(frame, str):
                    self._control(json.loads(frame))
                elif frame and frame[0] == MESSAGE_DATA:
                    sub, log_time = struct.unpack_from("<IQ", frame, 1)
                    topic = self._subscriptions.get(sub)
                    if topic is not None:
                        with self._lock:
                            self.received.setdefault(topic, []).append((log_time, bytes(frame[13:]), time.monotonic()))
        except ConnectionClosed:
            return

    def _control(self, msg: dict[str, Any]) -> None:
        if msg.get("op") == "serverInfo":
            self.server_info = msg
        elif msg.get("op") == "advertise":
            new = []
            for ch in msg["channels"]:
                self.channels[ch["id"]] = ch
                if self.topics is None or ch["topic"] in self.topics:
                    sub = len(self._subscriptions) + 1
                    self._subscriptions[sub] = ch["topic"]
                    new.append({"id": sub, "channelId": ch["id"]})
            if new:
                self.ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))

    def messages(self, topic: str) -> list[tuple[int, bytes, float]]:
        with self._lock:
            return list(self.received.get(topic, []))

    def decode(self, topic: str, payload: bytes) -> Any:
        """A message of ``topic`` decoded: JSON as a dict, protobuf (Foxglove schemas) as a
        protobuf message built from the schema the server advertised (needs mcap-protobuf-support)."""
        ch = next(c for c in self.channels.values() if c["topic"] == topic)
        if ch["encoding"] == "json":
            return json.loads(payload)
        from mcap.records import Schema
        from mcap_protobuf.decoder import DecoderFactory

        schema = Schema(id=ch["id"], name=ch["schemaName"], encoding="protobuf", data=base64.b64decode(ch["schema"]))
        decoder = DecoderFactory().decoder_for("protobuf", schema)
        assert decoder is not None
        return decoder(payload)

    def close(self) -> None:
        self.ws.close()
        self._thread.join(timeout=5.0)

    def __enter__(self) -> "LiveViewer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
