"""Authentication tags of bus samples (pure: hashlib and hmac, no Zenoh, no clock).

In the spirit of MAVLink 2 signing, for peer mode (no router, no access control) and as defence
in depth behind the mTLS + ACL router: a key shared by the two robots of a pair, a per-signer
counter, a replay window.

Key. ``zenoh.signing_key_file`` holds 32 bytes (64 hex digits or raw). Each pair signs with
:func:`pair_key` ``= BLAKE2b(key, "marsupial/<pair>")``, so one fleet key file still gives every
pair a key of its own and a sample of one pair never verifies in another.

Tag. Every signed sample carries, at the end of its Zenoh attachment (after any attachment of
its own, e.g. rmw_zenoh's), a 36-byte trailer::

    magic  b"mAs1"        4 bytes
    signer                8 bytes   random per signer (a publisher, a clock relay): its identity
    counter               8 bytes   big-endian uint64: microseconds since the Unix epoch, strictly
                                    increasing per signer (max(previous + 1, wall clock))
    mac                  16 bytes   BLAKE2b-128 keyed with the pair key over the key expression,
                                    signer, counter, the attachment before the trailer and the payload

Verification (:class:`Verifier`, one per subscription): no trailer -> ``unsigned``; a MAC that
does not match -> ``signature``; a counter not above the signer's last one, or more than
:data:`REPLAY_WINDOW_S` away from the receiver's wall clock -> ``replay`` (a recording replayed
later, or a clock skew larger than the window: keep the robots' clocks within it, as MAVLink
does). A verified sample's source is its signer (``"signer:<hex>"``): the carrier feed binds to
it instead of Zenoh's unauthenticated ``source_info``, so a copier without the key can neither
take over a signer's sequence nor pass as it.
"""
from __future__ import annotations

import hashlib
import hmac
import os
import struct
from typing import Any

from mission.bus.wire import WireError

MAGIC = b"mAs1"
TRAILER = struct.Struct(">4s8sQ16s")  # magic, signer, counter, mac
TRAILER_BYTES = TRAILER.size  # 36
MAC_BYTES = 16
REPLAY_WINDOW_S = 60.0  # [s] as MAVLink 2 signing's one-minute window for a new stream
MAX_SIGNERS = 64  # signers remembered per verifier (only key holders create one)
SOURCE_PREFIX = "signer:"


def pair_key(key: bytes, pair: str) -> bytes:
    """The 32-byte key pair ``pair`` signs with, derived from the key file's ``key`` (32 bytes)."""
    if len(key) != 32:
        raise ValueError("a bus signing key has 32 bytes")
    return hashlib.blake2b(f"marsupial/{pair}".encode(), key=key, digest_size=32).digest()


_HEAD = struct.Struct(">H")
_COUNT = struct.Struct(">QI")


def _keyed(key: bytes) -> Any:
    """The keyed BLAKE2b-128 state before any data (copied per sample: the key is hashed once)."""
    return hashlib.blake2b(key=key, digest_size=MAC_BYTES)


def _mac(keyed: Any, key_expr: str, signer: bytes, counter: int, inner: bytes, payload: bytes) -> bytes:
    h = keyed.copy()
    expr = key_expr.encode()
    h.update(b"".join((_HEAD.pack(len(expr)), expr, signer, _COUNT.pack(counter, len(inner)), inner)))
    h.update(payload)
    return h.digest()


class Signer:
    """Signs samples as one signer (a random 8-byte identity unless ``signer`` is given).
    Not thread-safe: one thread signs, or the caller locks."""

    def __init__(self, key: bytes, signer: bytes | None = None) -> None:
        self._keyed = _keyed(key)
        self.signer = signer if signer is not None else os.urandom(8)
        if len(self.signer) != 8:
            raise ValueError("a signer identity has 8 bytes")
        self.counter = 0

    @property
    def source(self) -> str:
        """This signer as a verified sample's source (:attr:`Verifier` returns it)."""
        return SOURCE_PREFIX + self.signer.hex()

    def attachment(self, key_expr: str, payload: bytes, now_us: int, inner: bytes = b"") -> bytes:
        """The attachment to put with ``payload`` on ``key_expr``: ``inner`` (the sample's own
        attachment, may be empty) and the trailer. ``now_us`` [us] wall clock since the Unix epoch."""
        self.counter = max(self.counter + 1, int(now_us))
        mac = _mac(self._keyed, key_expr, self.signer, self.counter, inner, payload)
        return inner + TRAILER.pack(MAGIC, self.signer, self.counter, mac)


class Verifier:
    """Checks the tags of one subscription's samples (not thread-safe: one callback thread, or
    the caller locks)."""

    def __init__(self, key: bytes, window_s: float = REPLAY_WINDOW_S) -> None:
        self._keyed = _keyed(key)
        self.window_us = int(window_s * 1e6)
        self._last: dict[bytes, int] = {}  # signer -> its last counter, oldest first

    def verify(self, key_expr: str, payload: bytes, attachment: bytes | None, now_us: int) -> tuple[str, bytes]:
        """(source ``"signer:<hex>"``, the attachment before the trailer) of an authentic, fresh
        sample; raises :class:`WireError` ``unsigned``, ``signature`` or ``replay``."""
        if attachment is None or len(attachment) < TRAILER_BYTES:
            raise WireError("unsigned", "no authentication tag")
        magic, signer, counter, mac = TRAILER.unpack_from(attachment, len(attachment) - TRAILER_BYTES)
        if magic != MAGIC:
            raise WireError("unsigned", "no authentication tag")
        inner = attachment[:-TRAILER_BYTES]
        if not hmac.compare_digest(mac, _mac(self._keyed, key_expr, signer, counter, inner, payload)):
            raise WireError("signature", f"bad tag from signer {signer.hex()}")
        if now_us - counter > self.window_us:
            raise WireError("replay", f"signer {signer.hex()}: counter {(now_us - counter) / 1e6:.1f} s old "
                            f"(window {self.window_us / 1e6:g} s; or the clocks differ)")
        last = self._last.get(signer)
        if last is not None and counter <= last:
            raise WireError("replay", f"signer {signer.hex()}: counter {counter} not after {last}")
        if last is None and counter - now_us > self.window_us:
            raise WireError("replay", f"signer {signer.hex()}: counter {(counter - now_us) / 1e6:.1f} s ahead "
                            f"(window {self.window_us / 1e6:g} s; or the clocks differ)")
        if last is None and len(self._last) >= MAX_SIGNERS:
            del self._last[next(iter(self._last))]
        self._last[signer] = counter
        return SOURCE_PREFIX + signer.hex(), inner
