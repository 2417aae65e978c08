"""A ``.tlog`` as QGroundControl and ``mavlogdump.py`` read it: each packet prefixed by an 8-byte
big-endian microsecond timestamp (wall time, from the injected clock and an epoch taken at open)."""
from __future__ import annotations

import struct
import threading
import time
from pathlib import Path
from typing import IO

from mission.time.clock import Clock


class Tlog:
    """Appends packets to ``path`` (thread-safe); :meth:`close` is idempotent."""

    def __init__(self, path: str | Path, clock: Clock) -> None:
        self.path, self._clock = Path(path), clock
        self._file: IO[bytes] | None = open(self.path, "wb")
        self._epoch_us = time.time_ns() // 1000 - int(clock.now() * 1e6)
        self._lock = threading.Lock()

    def write(self, packet: bytes | bytearray) -> None:
        with self._lock:
            if self._file is None:
                return
            usec = (self._epoch_us + int(self._clock.now() * 1e6)) & ~3
            self._file.write(struct.pack(">Q", usec) + bytes(packet))

    def flush(self) -> None:
        with self._lock:
            if self._file is not None:
                self._file.flush()

    def close(self) -> None:
        with self._lock:
            file, self._file = self._file, None
        if file is not None:
            file.close()
