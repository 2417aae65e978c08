"""How a command's process ends: on SIGINT or SIGTERM, and with its supervisor.

**Stop signals** (:func:`on_stop_signals`): a command's SIGINT and SIGTERM run its stop on a thread of
their own, never inside Python's signal handler. That handler runs in the main thread between two
bytecodes, even while the main thread holds a lock, so a handler that takes one (``Event.set`` does)
can wait for ever on a lock its own thread holds (docs/safety.md). The handler does nothing: the
signal's C handler writes its number to a socket (``signal.set_wakeup_fd``), and a thread that
reads it calls the stop.

**Supervision** (:func:`end_with_parent`): a supervisor (``marsupial demo``, the test suite) names
itself in the environment variable ``MARSUPIAL_PARENT_PID`` before it starts our commands. A command
started that way watches its parent: when the parent is gone (even by SIGKILL, when it had no chance
to stop its children), the command gets SIGTERM, its normal clean stop (a vehicle stops streaming, a
carrier stops, a mission closes its log), and is forced out 5 s later if that stop hangs. Without
the variable nothing is watched: a command started by a person or a service manager lives on its own
terms.
"""
from __future__ import annotations

import contextlib
import logging
import os
import signal
import socket
import threading
import time
from collections.abc import Callable, Iterator
from types import FrameType

log = logging.getLogger(__name__)

PARENT_PID_ENV = "MARSUPIAL_PARENT_PID"
POLL_S = 0.5  # [s] how often the parent is looked at (wall time)
FORCE_AFTER_S = 5.0  # [s] after SIGTERM, the process is forced out if still alive


def supervise_children() -> None:
    """Name this process as the supervisor of the commands it starts from now on."""
    os.environ[PARENT_PID_ENV] = str(os.getpid())


def end_with_parent() -> bool:
    """If a supervisor named itself, watch it on a daemon thread; returns whether one did. The
    variable is consumed, so this process's own children are not tied to the grandparent."""
    value = os.environ.pop(PARENT_PID_ENV, "")
    try:
        parent = int(value)
    except ValueError:
        return False
    if parent == os.getpid():  # the supervisor runs a command in its own process (a test calling main())
        os.environ[PARENT_PID_ENV] = value
        return False
    threading.Thread(target=_watch, args=(parent,), name="end-with-parent", daemon=True).start()
    return True


def _watch(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(POLL_S)
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(FORCE_AFTER_S)
    os._exit(143)


STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _noted(signum: int, frame: FrameType | None) -> None:
    """Python's handler of a stop signal: nothing (its C handler has already woken the watcher)."""


@contextlib.contextmanager
def on_stop_signals(stop: Callable[[int], None]) -> Iterator[bool]:
    """While inside, SIGINT and SIGTERM call ``stop(signum)`` on the thread "stop-signals", once per
    signal received; the handlers and wake-up socket that were there before are put back on exit.
    Yields whether it is installed: only the main thread can take signals, so from another thread
    (a test calling a command's function) nothing is installed and it yields False."""
    if threading.current_thread() is not threading.main_thread():
        yield False
        return
    reader, writer = socket.socketpair()
    writer.setblocking(False)  # the C handler must never block
    previous_fd = signal.set_wakeup_fd(writer.fileno(), warn_on_full_buffer=False)
    previous = {sig: signal.signal(sig, _noted) for sig in STOP_SIGNALS}
    watcher = threading.Thread(target=_watch_signals, args=(reader, stop), name="stop-signals", daemon=True)
    watcher.start()
    try:
        yield True
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        signal.set_wakeup_fd(previous_fd)
        reader.shutdown(socket.SHUT_RD)  # the watcher's recv returns b"" and it ends
        watcher.join(timeout=5.0)
        reader.close()
        writer.close()


def _watch_signals(reader: socket.socket, stop: Callable[[int], None]) -> None:
    stops = {int(s) for s in STOP_SIGNALS}
    while True:
        try:
            data = reader.recv(64)
        except OSError:
            return
        if not data:
            return
        for signum in data:
            if signum in stops:
                try:
                    stop(signum)
                except Exception:  # noqa: BLE001  (a failing stop is logged; the next signal tries again)
                    log.exception("stopping on %s failed", signal.Signals(signum).name)
