"""The MCAP file and the live server behind a flight data log, fed by a worker thread.

:class:`DataLog` opens a foxglove-sdk context with an MCAP writer on it and, when asked, the
SDK's WebSocket server on the same context: a message logged on one of its channels goes to
both. The caller's thread only queues (``submit``: one ``SimpleQueue.put``); a worker thread
makes the messages and logs them, so the control loop never waits for encoding, compression or
a slow viewer.

Flush policy: the SDK writes a chunk's header before its messages and its length when the chunk
ends, so a killed process leaves an unfinished last chunk that a reader cannot open. The worker
ends the chunk (``MCAPWriter.flush``) every ``flush_period_s`` of the mission clock (1 s): a
killed process leaves every message up to the last flush readable
(:func:`mission.flightdata.read.read_messages` stops at the unfinished chunk).

Times are nanoseconds since the Unix epoch, as Foxglove and ROS loggers write them: the file's
epoch (its ``clock`` metadata's ``epoch_ns``, :func:`log_epoch_ns`) plus the mission clock's
time. In real time the epoch is the wall clock at the clock's zero, so at speed 1 the times are
wall-clock times and the files of a ``run`` and a ``carrier`` line up; in lockstep the demo gives
its processes one epoch and the simulated clock they share does the rest.
"""
from __future__ import annotations

import ipaddress
import logging
import queue
import threading
import time
from pathlib import Path
from typing import Any, NamedTuple

from mission.errors import ConfigError
from mission.flightdata.topics import JSON_SCHEMAS

log = logging.getLogger(__name__)

DEFAULT_LIVE = "127.0.0.1:8765"  # Foxglove's default WebSocket port, on loopback
FLUSH_PERIOD_S = 1.0  # [s] of mission clock between two finished chunks
DRAIN_WALL_S = 0.02  # [s, wall] the worker sleeps after emptying its queue (it wakes at most this often)
_STOP = object()


class LiveAddress(NamedTuple):
    """Where the live WebSocket server binds: host (name or address) and TCP port (0: any free)."""

    host: str
    port: int

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"ws://{host}:{self.port}"


def parse_live(value: str, field: str = "--live") -> LiveAddress:
    """``HOST:PORT`` (``[::1]:8765`` for IPv6), ``:PORT`` or ``PORT`` (host 127.0.0.1) as a
    :class:`LiveAddress`; a :class:`ConfigError` naming ``field`` otherwise."""
    text = value.strip()
    host, sep, port_text = text.rpartition(":")
    if not sep:
        host, port_text = "", text
    host = host.strip("[]") or "127.0.0.1"
    try:
        port = int(port_text)
    except ValueError:
        raise ConfigError(field, value, "must be HOST:PORT (e.g. 127.0.0.1:8765) or a port number") from None
    if not 0 <= port <= 65535:
        raise ConfigError(field, value, "the port must be in 0..65535")
    return LiveAddress(host, port)


def is_loopback(host: str) -> bool:
    """Whether ``host`` binds the loopback interface only (``localhost``, 127.0.0.0/8, ::1)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def ns(t_s: float) -> int:
    """Mission-clock time [s] as nanoseconds (never negative)."""
    return max(int(round(t_s * 1e9)), 0)


def log_epoch_ns(clock: Any, shared_epoch_ns: int | None = None) -> int:
    """[ns since the Unix epoch] the zero of ``clock``'s time is: ``shared_epoch_ns`` when given
    (the demo's, one for all its processes in lockstep), else the wall clock when the clock read
    zero (a real-time clock scaled by ``speed``: now minus its time over its speed; a lockstep
    clock without a shared epoch: now minus its time)."""
    from mission.time.clock import LockstepClock

    if shared_epoch_ns is not None:
        return int(shared_epoch_ns)
    rate = 1.0 if isinstance(clock, LockstepClock) else getattr(clock, "speed", 1.0)
    return time.time_ns() - int(round(clock.now() / rate * 1e9))


def clock_metadata(clock: Any, note: str, lockstep_source: str, epoch_ns: int | None = None) -> dict[str, str]:
    """The ``clock`` metadata of a flight data file: its log times are ``epoch_ns`` (see
    :func:`log_epoch_ns`, given or taken now) plus ``clock``'s time (the mission clock), in ns;
    ``lockstep_source`` says what a lockstep clock follows."""
    from mission.time.clock import LockstepClock

    if isinstance(clock, LockstepClock):
        source = f"lockstep: {lockstep_source}"
    else:
        source = f"{type(clock).__name__}: the wall clock (monotonic) x{getattr(clock, 'speed', 1.0):g}"
    return {"clock": "mission", "unit": "ns since the Unix epoch: epoch_ns + the mission clock's time",
            "epoch_ns": str(log_epoch_ns(clock, epoch_ns)), "source": source, "note": note,
            "wall_start_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def timestamp(t_ns: int) -> Any:
    """A ``foxglove.messages.Timestamp`` of ``t_ns`` [ns since the Unix epoch]."""
    from foxglove.messages import Timestamp

    return Timestamp(t_ns // 1_000_000_000, t_ns % 1_000_000_000)


def start_live(address: LiveAddress, context: Any, name: str) -> Any:
    """The SDK's WebSocket server on ``address`` for ``context`` (with the Time capability: the
    mission clock is the viewer's clock). A taken port raises
    :class:`~mission.errors.PortInUse` naming its holder; any other failure a
    :class:`ConfigError` naming ``--live``."""
    import foxglove
    from foxglove.websocket import Capability

    if not is_loopback(address.host):
        log.warning("live view on %s is not loopback: anyone who can reach it sees the flight", address.url)
    try:
        return foxglove.start_server(name=name, host=address.host, port=address.port, context=context,
                                     capabilities=[Capability.Time])
    except RuntimeError as exc:
        if "in use" in str(exc):
            from mission.port_holder import port_in_use

            raise port_in_use(f"Foxglove live view {address.url}", address.host, address.port, "tcp") from None
        raise ConfigError("--live", f"{address.host}:{address.port}", f"cannot start the live server: {exc}") from None


class DataLog:
    """An MCAP file at ``path`` (and a live server at ``live``, if given) whose messages a worker
    thread makes from what :meth:`submit` queues.

    ``metadata``: MCAP metadata records written first (name -> string map; ``clock``'s ``epoch_ns``
    is the epoch of the log times, 0 without one). Subclasses create
    their channels with :meth:`channel` and implement :meth:`handle` (runs on the worker);
    :meth:`finish` ends it all.
    Errors in the worker are logged, counted (``errors``) and never reach the caller.
    """

    def __init__(self, path: str | Path, *, name: str, metadata: dict[str, dict[str, str]],
                 live: LiveAddress | None = None, flush_period_s: float = FLUSH_PERIOD_S) -> None:
        import foxglove
        from foxglove.mcap import MCAPCompression, MCAPWriteOptions

        self.path = Path(path)
        self.context = foxglove.Context()
        self.server = start_live(live, self.context, name) if live is not None else None
        try:
            options = MCAPWriteOptions(compression=MCAPCompression.Zstd, compression_threads=0)
            self.writer = foxglove.open_mcap(self.path, allow_overwrite=True, context=self.context,
                                             writer_options=options)
        except Exception:
            if self.server is not None:
                self.server.stop()
            raise
        for record_name, values in metadata.items():
            self.writer.write_metadata(record_name, values)
        self.epoch_ns = int(metadata.get("clock", {}).get("epoch_ns", 0))
        self.flush_period_s = flush_period_s
        self.errors = 0
        self._closed = False
        self._next_flush_s: float | None = None
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._run, name=f"flightdata-{name}", daemon=True)
        self._thread.start()

    @property
    def live_port(self) -> int | None:
        """The live server's TCP port (the one bound when ``live`` asked for port 0), or None."""
        return None if self.server is None else int(self.server.port)

    def channel(self, topic: str, schema: str) -> Any:
        """A channel on this log's context: a typed foxglove-sdk channel for ``foxglove.<Name>``
        schemas, a JSON channel with :data:`JSON_SCHEMAS` ``[schema]`` otherwise."""
        import foxglove
        import foxglove.channels

        if schema.startswith("foxglove."):
            return getattr(foxglove.channels, f"{schema.split('.', 1)[1]}Channel")(topic, context=self.context)
        return foxglove.Channel(topic, schema=JSON_SCHEMAS[schema], context=self.context)

    def submit(self, t_s: float, item: Any) -> None:
        """Queue ``item`` of mission-clock time ``t_s`` [s] for the worker (returns at once)."""
        self._queue.put((t_s, item))

    def log_ns(self, t_s: float) -> int:
        """The log time [ns since the Unix epoch] of mission-clock time ``t_s`` [s]."""
        return self.epoch_ns + ns(t_s)

    def handle(self, t_s: float, item: Any) -> None:
        """Make and log the messages of ``item`` (the worker's thread)."""
        raise NotImplementedError

    def _run(self) -> None:
        while True:
            entry = self._queue.get()
            while entry is not None:
                if entry is _STOP:
                    return
                self._log(*entry)
                try:
                    entry = self._queue.get_nowait()
                except queue.Empty:
                    entry = None
            # Drained: let the next entries gather for a while instead of waking on each (a wake per
            # tick, and the GIL handed over each time, cost the control loop's process more CPU than
            # the messages' own making). At most DRAIN_WALL_S later, on the mission's clock the same.
            time.sleep(DRAIN_WALL_S)

    def _log(self, t_s: float, item: Any) -> None:
        """Log one queued ``item`` of mission-clock time ``t_s`` [s]; end the chunk when due."""
        try:
            self.handle(t_s, item)
            if self.server is not None:
                self.server.broadcast_time(self.log_ns(t_s))
            if self._next_flush_s is None:
                self._next_flush_s = t_s + self.flush_period_s
            elif t_s >= self._next_flush_s:
                self.writer.flush()  # end the chunk: on disk and readable whatever happens next
                self._next_flush_s = t_s + self.flush_period_s
        except Exception as exc:  # the flight data never stops the flight
            self.errors += 1
            if self.errors <= 3:
                log.warning("flight data %s: %s: %s", self.path.name, type(exc).__name__, exc)

    def finish(self, metadata: dict[str, dict[str, str]] | None = None, timeout_s: float = 10.0) -> None:
        """Let the worker finish what was queued, write ``metadata``, finish the file (summary,
        footer) and stop the live server. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._queue.put(_STOP)
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            log.warning("flight data %s: the writer did not finish within %.0f s", self.path.name, timeout_s)
        try:
            for record_name, values in (metadata or {}).items():
                self.writer.write_metadata(record_name, values)
            self.writer.close()
        finally:
            if self.server is not None:
                self.server.stop()
