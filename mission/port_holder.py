"""Who holds a local port: the message a user gets when a port we bind is already taken.

Linux only (``/proc/net/{udp,tcp}[6]`` and ``/proc/<pid>/fd``); elsewhere, or for another
user's process, the holder is simply unknown. Pure reading, no side effects.
"""
from __future__ import annotations

import errno
import os
from pathlib import Path

from mission.errors import PortInUse


def _inodes(port: int, proto: str) -> set[str]:
    """Socket inodes bound to local ``port`` in ``/proc/net/<proto>`` and ``<proto>6``."""
    found: set[str] = set()
    for table in (f"/proc/net/{proto}", f"/proc/net/{proto}6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            parts = line.split()
            if len(parts) > 9 and int(parts[1].rsplit(":", 1)[1], 16) == port:
                found.add(parts[9])
    return found


def port_holder(port: int, proto: str = "udp") -> tuple[int, str] | None:
    """``(pid, command line)`` of a process holding local ``port`` (``proto`` "udp" or "tcp"),
    or None when unknown."""
    inodes = {f"socket:[{i}]" for i in _inodes(port, proto) if i != "0"}
    if not inodes:
        return None
    for pid_dir in Path("/proc").iterdir():
        if not pid_dir.name.isdigit():
            continue
        try:
            fds = list((pid_dir / "fd").iterdir())
        except OSError:  # gone, or another user's
            continue
        for fd in fds:
            try:  # one fd closed meanwhile (a busy holder) must not hide the others
                held = os.readlink(fd) in inodes
            except OSError:
                continue
            if held:
                try:
                    cmd = (pid_dir / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip()
                except OSError:
                    cmd = ""
                return int(pid_dir.name), cmd
    return None


def port_in_use(what: str, host: str, port: int, proto: str = "udp", cls: type[PortInUse] = PortInUse) -> PortInUse:
    """The error to raise when binding ``host:port`` failed with EADDRINUSE; ``what`` names the
    endpoint for the user (e.g. "MAVLink udpin:127.0.0.1:14540")."""
    holder = port_holder(port, proto)
    who = (f"held by process {holder[0]} ({holder[1][:120]})" if holder
           else "held by another process (not one of yours, or not found)")
    return cls(f"cannot open {what}: {proto.upper()} port {host}:{port} is already in use, {who}. "
                     "Stop that process, or choose another port.")


def is_addr_in_use(exc: BaseException) -> bool:
    return isinstance(exc, OSError) and exc.errno == errno.EADDRINUSE
