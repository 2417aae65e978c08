"""Small helpers for processes and tests that talk over loopback."""
from __future__ import annotations

import os
import random
import signal
import socket
import struct
import subprocess
import threading
import time
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path
from typing import IO, TypeVar

T = TypeVar("T")


#: Ports :func:`free_port` hands out: below Linux's ephemeral range (32768-60999), so no socket
#: bound to port 0 and no outgoing connection's source port takes one between its pick and its bind.
PORT_RANGE = (20000, 32768)
#: ``"i/n"``: this process picks in lane ``i`` of ``n`` equal lanes of :data:`PORT_RANGE` (one per
#: pytest-xdist worker, so parallel workers never pick the same port); inherited by children.
LANE_ENV = "MARSUPIAL_PORT_LANE"
_MIN_LANE_WIDTH = 64

_cursor: dict[tuple[int, int], int] = {}  # lane -> next port to try
_cursor_lock = threading.Lock()


def port_lane() -> tuple[int, int]:
    """This process's lane ``[lo, hi)`` of :data:`PORT_RANGE` (all of it without :data:`LANE_ENV`);
    ``ValueError`` naming the variable if it is malformed."""
    lo, hi = PORT_RANGE
    spec = os.environ.get(LANE_ENV, "").strip()
    if not spec:
        return lo, hi
    try:
        index, count = (int(v) for v in spec.split("/"))
    except ValueError:
        raise ValueError(f"{LANE_ENV}={spec!r}: expected 'i/n' (lane i of n, 0 <= i < n)") from None
    width = (hi - lo) // max(count, 1)
    if not (count >= 1 and 0 <= index < count and width >= _MIN_LANE_WIDTH):
        raise ValueError(f"{LANE_ENV}={spec!r}: expected 0 <= i < n and n <= {(hi - lo) // _MIN_LANE_WIDTH}")
    return lo + index * width, lo + (index + 1) * width


def _bindable(port: int, kind: int) -> bool:
    with socket.socket(socket.AF_INET, kind) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    """A free port on 127.0.0.1 (TCP by default; ``socket.SOCK_DGRAM`` for UDP), for an endpoint
    that must be named before the process that binds it starts.

    Taken in turn from a random start in this process's :func:`port_lane` (never one it handed
    out recently), and checked free by binding it."""
    lo, hi = port_lane()
    width = hi - lo
    with _cursor_lock:
        start = _cursor.get((lo, hi), lo + random.randrange(width))
        for step in range(width):
            port = lo + (start - lo + step) % width
            if _bindable(port, kind):
                _cursor[(lo, hi)] = lo + (port - lo + 1) % width
                return port
    raise OSError(f"no free {'UDP' if kind == socket.SOCK_DGRAM else 'TCP'} port in {lo}-{hi - 1} on 127.0.0.1")


def wait_for(predicate: Callable[[], T], timeout_s: float = 10.0, what: str = "condition") -> T:
    """Poll ``predicate`` (wall clock) until it returns a truthy value, which is returned;
    raise ``AssertionError`` naming ``what`` after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(0.002)


def stop_process(proc: subprocess.Popen, timeout_s: float = 5.0) -> None:
    """SIGTERM (our commands exit cleanly on it), then SIGKILL after ``timeout_s``; always reaped."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)  # Linux asm-generic value (x86_64, arm64)
_STAMP_CMSG_LEN = socket.CMSG_SPACE(16)


def enable_rx_stamps(sock: socket.socket) -> socket.socket:
    """Ask the kernel to stamp every datagram ``sock`` receives (SO_TIMESTAMPNS, CLOCK_REALTIME);
    read them with :func:`recv_stamped`. Returns ``sock``."""
    sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    return sock


def recv_stamped(sock: socket.socket) -> tuple[bytes, int, tuple[str, int]]:
    """One datagram, its kernel receive time [ns, CLOCK_REALTIME] and its sender.

    The stamp is the arrival at the socket, free of the reader's own scheduling; without one
    (stamps not enabled) it is the user-space receive time."""
    data, ancillary, _flags, address = sock.recvmsg(65535, _STAMP_CMSG_LEN)
    for level, kind, payload in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(payload) >= 16:
            sec, nsec = struct.unpack("qq", payload[:16])
            return data, sec * 1_000_000_000 + nsec, address
    return data, time.time_ns(), address


def child_stderr(stack: ExitStack, folder: Path | None, name: str) -> IO[str] | None:
    """Where a child process's stderr (its log) goes: the file ``folder/name.log``, closed with
    ``stack``, or this process's own stderr (``folder`` None)."""
    if folder is None:
        return None
    folder.mkdir(parents=True, exist_ok=True)
    out = open(folder / f"{name}.log", "w", encoding="utf-8")  # noqa: SIM115 - closed with the stack
    stack.callback(out.close)
    return out
