"""A keyless relay between two Zenoh routers that delivers the carrier's real, signed states
late and in order (the "late but authentic states" attack), in lockstep.

The carrier (and the mock vehicle's deck) sit on router A, the mission on router B; the relay
is two sessions of this test process (the routers themselves). It forwards, byte for byte with
their authentication tags:

- B -> A at once: the passenger's status and phase, the mission's ``clock/time`` calls;
- A -> B: the carrier's states, each held until the simulated time has passed its stamp plus
  the delay (once :attr:`DelayRelay.active`: from the first RETURNING status on, or from the
  start with ``from_phase=None``);
- the liveliness tokens of both sides (mirrored).

The lockstep clock is the simulation's own, not part of the attack: at each of the carrier's
``clock/ready`` answers the relay releases the states now due and answers the mission itself,
naming the last state it released (signed with the pair's key: the mission waits for the
sample a ready names, and a late sample named by the carrier's ready would stall the clock).
"""
from __future__ import annotations

import json
import queue
import threading
from typing import Any

import zenoh

from mission.bus.auth import BusAuth
from mission.bus.session import keys
from mission.bus.lockstep import clock_keys


class DelayRelay:
    """Relay pair ``pair`` from router session ``a`` (carrier side) to ``b`` (mission side),
    delaying the carrier's states by ``delay_s`` [s] of simulated time once the passenger
    reports ``from_phase`` (None: from the start). ``key``: the pair's 32-byte bus key (it signs
    the relay's own clock answers only)."""

    def __init__(self, a: zenoh.Session, b: zenoh.Session, pair: str, delay_s: float, key: bytes,
                 from_phase: str | None = "RETURNING") -> None:
        self.delay_s, self.from_phase = delay_s, from_phase
        self.active = from_phase is None
        self.active_at_s: float | None = 0.0 if self.active else None
        self.released = 0
        self.max_delay_s = 0.0  # largest (release time - stamp) of a released state [s]
        k = keys(pair)
        time_key, ready_key = clock_keys(pair)
        self._signer = BusAuth(key, pair).signer()
        self._ready_key = ready_key
        self._lock = threading.Lock()
        self._held: list[tuple[float, int, bytes, bytes | None]] = []  # (stamp, seq, payload, attachment)
        self._seen_seq = -1
        self._pending: tuple[int, int, int] | None = None  # the carrier's last ready (t ns, wake ns, seq)
        self._last_seq = -1
        self._jobs: queue.Queue[Any] = queue.Queue()
        self._entities: list[Any] = []
        block = zenoh.CongestionControl.BLOCK
        self._pub_state = b.declare_publisher(k.carrier_state, congestion_control=block, express=True)
        self._pub_ready = b.declare_publisher(ready_key, congestion_control=block, express=True)
        self._pub_time = a.declare_publisher(time_key, congestion_control=block, express=True)
        self._pub_passenger = {key: a.declare_publisher(key, congestion_control=block, express=True)
                               for key in (k.passenger_state, k.passenger_phase)}
        self._entities += [self._pub_state, self._pub_ready, self._pub_time, *self._pub_passenger.values()]
        self._tokens: dict[str, Any] = {}
        self._entities += [
            a.declare_subscriber(k.carrier_state, self._on_state),
            a.declare_subscriber(ready_key, self._on_ready),
            b.declare_subscriber(time_key, lambda s: self._jobs.put((self._pub_time, s))),
            b.declare_subscriber(k.passenger_state, lambda s: self._jobs.put((self._pub_passenger[k.passenger_state], s))),
            b.declare_subscriber(k.passenger_phase, self._on_phase),
            a.liveliness().declare_subscriber(k.carrier_alive, lambda s: self._mirror(b, s), history=True),
            b.liveliness().declare_subscriber(k.passenger_alive, lambda s: self._mirror(a, s), history=True),
        ]
        self._thread = threading.Thread(target=self._run, name="delay-relay", daemon=True)
        self._thread.start()

    # -- Zenoh's threads: record and queue, never block
    def _mirror(self, session: zenoh.Session, sample: zenoh.Sample) -> None:
        self._jobs.put(("token", session, str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT))

    def _on_phase(self, sample: zenoh.Sample) -> None:
        phase = sample.payload.to_bytes().decode(errors="replace")
        if not self.active and phase == self.from_phase:
            self.active = True
        self._jobs.put((self._pub_passenger[str(sample.key_expr)], sample))

    def _on_state(self, sample: zenoh.Sample) -> None:
        raw = sample.payload.to_bytes()
        attachment = None if sample.attachment is None else sample.attachment.to_bytes()
        body = json.loads(raw)
        with self._lock:
            self._held.append((float(body["stamp"]), int(body["seq"]), raw, attachment))
            self._seen_seq = max(self._seen_seq, int(body["seq"]))
        self._jobs.put(("release",))

    def _on_ready(self, sample: zenoh.Sample) -> None:
        t_ns, wake_ns, seq = (int(v) for v in sample.payload.to_bytes().decode().split()[:3])
        with self._lock:
            self._pending = (t_ns, wake_ns, seq)
        self._jobs.put(("release",))

    # -- the relay's own thread: every put
    def _run(self) -> None:
        while True:
            job = self._jobs.get()
            if job is None:
                return
            try:
                if job[0] == "release":
                    self._release()
                elif job[0] == "token":
                    _, session, key, present = job
                    if present and key not in self._tokens:
                        self._tokens[key] = session.liveliness().declare_token(key)
                    elif not present and key in self._tokens:
                        self._tokens.pop(key).undeclare()
                else:
                    pub, sample = job
                    att = None if sample.attachment is None else sample.attachment.to_bytes()
                    pub.put(sample.payload.to_bytes(), attachment=att)
            except zenoh.ZError:
                return  # closing

    def _release(self) -> None:
        """At a carrier's ready whose state has come: put the states now due, then the ready."""
        with self._lock:
            pending = self._pending
            if pending is None or self._seen_seq < pending[2]:
                return
            self._pending = None
            t_s = pending[0] / 1e9
            if self.active and self.active_at_s is None:
                self.active_at_s = t_s
            due_by = t_s - (self.delay_s if self.active else 0.0)
            due = [h for h in self._held if h[0] <= due_by + 1e-9]
            self._held = [h for h in self._held if h[0] > due_by + 1e-9]
        for stamp, seq, raw, att in due:
            self._pub_state.put(raw, attachment=att)
            self._last_seq = seq
            self.released += 1
            self.max_delay_s = max(self.max_delay_s, t_s - stamp)
        text = f"{pending[0]} {pending[1]} {self._last_seq}".encode()
        self._pub_ready.put(text, attachment=self._signer.attachment(self._ready_key, text))

    def close(self) -> None:
        self._jobs.put(None)
        self._thread.join(timeout=5.0)
        for token in self._tokens.values():
            token.undeclare()
        for entity in reversed(self._entities):
            try:
                entity.undeclare()
            except zenoh.ZError:
                pass
