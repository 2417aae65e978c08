"""Key files: a 32-byte key as 64 hex digits or 32 raw bytes (MAVLink 2 signing, bus signing)."""
from __future__ import annotations

import os
from pathlib import Path

from mission.errors import ConfigError


def read_key_file(path: str | os.PathLike[str], field: str) -> bytes:
    """The 32-byte key of the file at ``path`` (64 hex digits, surrounding whitespace allowed, or
    32 raw bytes). Raises :class:`ConfigError` naming ``field`` if the file cannot be read or
    holds anything else; the key itself never appears in the message."""
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise ConfigError(field, str(path), f"cannot read the key file: {exc.strerror}") from None
    try:
        key = bytes.fromhex(raw.strip().decode("ascii"))
    except (UnicodeDecodeError, ValueError):
        key = raw
    if len(key) != 32:
        raise ConfigError(field, str(path), "must hold 32 bytes (raw) or 64 hex digits")
    return key
