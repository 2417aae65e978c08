"""Small helpers for processes and tests that talk over loopback."""
from __future__ import annotations

import signal
import socket
import struct
import subprocess
import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    """A port the OS just handed out on 127.0.0.1 (TCP by default; ``socket.SOCK_DGRAM`` for
    UDP), for an endpoint that must be named before the process that binds it starts."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


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
