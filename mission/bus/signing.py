"""Authentication tags of bus samples (pure: hashlib, hmac and ``cryptography``'s Ed25519; no
Zenoh, no clock).

In the spirit of MAVLink 2 signing, for peer mode (no router, no access control) and as defence
in depth behind the mTLS + ACL router: a per-signer counter, a replay window, and one of two keys.

Keys. **One key per robot** (:class:`Ed25519Signer`, :class:`Ed25519Verifier`): each robot signs
with its own Ed25519 private key and knows only the other robot's public key, so neither can
speak for the other. **A shared key** (:class:`Signer`, :class:`Verifier`; ``zenoh.signing_key_file``,
32 bytes), kept for a peer that cannot do otherwise (a ROS-2-shaped robot's commands and clock,
which belong to the carrier's own robot): each pair signs with :func:`pair_key` ``=
BLAKE2b(key, "marsupial/<pair>")``, so one fleet key file still gives every pair a key of its own;
whoever holds it can sign as either end.

Tag. Every signed sample carries, at the end of its Zenoh attachment (after any attachment of
its own, e.g. rmw_zenoh's), a trailer::

    magic  b"mAs1" (shared key) or b"mAs2" (Ed25519)   4 bytes
    signer                8 bytes   random per signer (a publisher, a clock relay): its stream
    counter               8 bytes   big-endian uint64: microseconds since the Unix epoch, strictly
                                    increasing per signer (max(previous + 1, wall clock))
    tag    16 bytes (BLAKE2b-128 keyed with the pair key) or 64 bytes (Ed25519 signature), over the
           key expression, signer, counter, the attachment before the trailer and the payload

Verification (one verifier per subscription): no trailer of the verifier's kind -> ``unsigned``;
a tag that does not verify -> ``signature``; then the signer's stream (:class:`Streams`): a
counter more than :data:`REPLAY_WINDOW_S` from the receiver's wall clock when the stream is new,
older than that, a copy of a counter already accepted, or just behind the stream's last (within
:data:`REORDER_S`) -> ``replay``. A counter that runs more than :data:`AHEAD_S` ahead of the
stream's own clock and of the receiver's (the largest lead of the stream's counters over the
receiver's wall clock so far, at least 0: a stream first heard on an old copy does not make the
real samples look ahead), or a sample never heard before that lies more than :data:`REORDER_S` behind the
stream's last, is a **contest**: two key holders sign under one signer id (an insider with the key
ahead of the real stream). The stream is then refused for good, both signers alike (``contest``):
the verifier cannot tell which is real, and silently keeping the one ahead is what let an insider
take a feed over. A verified sample's source is its signer (``"signer:<hex>"``): the feeds bind to
it instead of Zenoh's unauthenticated ``source_info``.
"""
from __future__ import annotations

import hashlib
import hmac
import os
import struct
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from mission.bus.wire import WireError

MAGIC = b"mAs1"  # shared key
MAGIC_ED25519 = b"mAs2"  # one key per robot
TRAILER = struct.Struct(">4s8sQ16s")  # magic, signer, counter, mac
TRAILER_BYTES = TRAILER.size  # 36
MAC_BYTES = 16
ED25519_TRAILER = struct.Struct(">4s8sQ64s")  # magic, signer, counter, Ed25519 signature
ED25519_TRAILER_BYTES = ED25519_TRAILER.size  # 84
REPLAY_WINDOW_S = 60.0  # [s] as MAVLink 2 signing's one-minute window for a new stream
AHEAD_S = 10.0  # [s] a counter this far ahead of its stream's own clock is a second signer (contest)
REORDER_S = 0.1  # [s] a never-heard counter at most this far behind the stream's last is late (replay), not a contest
HEARD = 4096  # counters remembered per signer (copies of them are replays, not contests)
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


def _signed_head(key_expr: str, signer: bytes, counter: int, inner: bytes) -> bytes:
    expr = key_expr.encode()
    return b"".join((_HEAD.pack(len(expr)), expr, signer, _COUNT.pack(counter, len(inner)), inner))


def _mac(keyed: Any, key_expr: str, signer: bytes, counter: int, inner: bytes, payload: bytes) -> bytes:
    h = keyed.copy()
    h.update(_signed_head(key_expr, signer, counter, inner))
    h.update(payload)
    return h.digest()


class Signer:
    """Signs samples as one signer with the pair's shared key (a random 8-byte identity unless
    ``signer`` is given). Not thread-safe: one thread signs, or the caller locks."""

    def __init__(self, key: bytes, signer: bytes | None = None) -> None:
        self._keyed = _keyed(key)
        self.signer = signer if signer is not None else os.urandom(8)
        if len(self.signer) != 8:
            raise ValueError("a signer identity has 8 bytes")
        self.counter = 0

    @property
    def source(self) -> str:
        """This signer as a verified sample's source (the verifier returns it)."""
        return SOURCE_PREFIX + self.signer.hex()

    def _next(self, now_us: int) -> int:
        self.counter = max(self.counter + 1, int(now_us))
        return self.counter

    def attachment(self, key_expr: str, payload: bytes, now_us: int, inner: bytes = b"") -> bytes:
        """The attachment to put with ``payload`` on ``key_expr``: ``inner`` (the sample's own
        attachment, may be empty) and the trailer. ``now_us`` [us] wall clock since the Unix epoch."""
        counter = self._next(now_us)
        mac = _mac(self._keyed, key_expr, self.signer, counter, inner, payload)
        return inner + TRAILER.pack(MAGIC, self.signer, counter, mac)


class Ed25519Signer(Signer):
    """Signs samples as one signer with this robot's own Ed25519 private key (a random 8-byte
    stream identity unless ``signer`` is given). Not thread-safe."""

    def __init__(self, private_key: Ed25519PrivateKey, signer: bytes | None = None) -> None:
        self._private = private_key
        self.signer = signer if signer is not None else os.urandom(8)
        if len(self.signer) != 8:
            raise ValueError("a signer identity has 8 bytes")
        self.counter = 0

    def attachment(self, key_expr: str, payload: bytes, now_us: int, inner: bytes = b"") -> bytes:
        counter = self._next(now_us)
        signature = self._private.sign(_signed_head(key_expr, self.signer, counter, inner) + payload)
        return inner + ED25519_TRAILER.pack(MAGIC_ED25519, self.signer, counter, signature)


@dataclass
class _Stream:
    """One signer's stream as a verifier saw it: the last counter, the largest lead of a counter
    over the receiver's wall clock [us], the counters accepted (newest last), and the contest."""

    last: int
    lead_us: int
    heard: deque[int] = field(default_factory=lambda: deque(maxlen=HEARD))
    heard_set: set[int] = field(default_factory=set)
    contest: str | None = None

    def remember(self, counter: int) -> None:
        if len(self.heard) == HEARD:
            self.heard_set.discard(self.heard[0])
        self.heard.append(counter)
        self.heard_set.add(counter)


class Streams:
    """The counter rules of the signers a verifier has heard (replay window, order, contest);
    see the module docstring. Not thread-safe."""

    def __init__(self, window_s: float = REPLAY_WINDOW_S) -> None:
        self.window_us = int(window_s * 1e6)
        self._streams: dict[bytes, _Stream] = {}  # oldest first
        self.contests = 0

    def contested(self, signer: bytes) -> str | None:
        """Why ``signer``'s stream is refused for good, or None."""
        st = self._streams.get(signer)
        return None if st is None else st.contest

    def check(self, signer: bytes, counter: int, now_us: int) -> None:
        """Accept ``counter`` of ``signer`` at receiver wall clock ``now_us`` [us], or raise
        :class:`WireError` ``replay`` or ``contest``."""
        who = signer.hex()
        st = self._streams.get(signer)
        if st is not None and st.contest is not None:
            raise WireError("contest", f"signer {who}: {st.contest}")
        if now_us - counter > self.window_us:
            raise WireError("replay", f"signer {who}: counter {(now_us - counter) / 1e6:.1f} s old "
                            f"(window {self.window_us / 1e6:g} s; or the clocks differ)")
        if st is None:
            if counter - now_us > self.window_us:
                raise WireError("replay", f"signer {who}: counter {(counter - now_us) / 1e6:.1f} s ahead "
                                f"(window {self.window_us / 1e6:g} s; or the clocks differ)")
            if len(self._streams) >= MAX_SIGNERS:
                del self._streams[next(iter(self._streams))]
            st = self._streams[signer] = _Stream(last=counter, lead_us=counter - now_us)
            st.remember(counter)
            return
        if counter > st.last:
            ahead_us = (counter - now_us) - max(st.lead_us, 0)  # a stream that began on an old copy: from the clock
            if ahead_us > AHEAD_S * 1e6:
                self._contest(st, f"counter {ahead_us / 1e6:.1f} s ahead of its own stream: a second signer with the key")
            st.last, st.lead_us = counter, max(st.lead_us, counter - now_us)
            st.remember(counter)
            return
        if counter in st.heard_set or (st.heard and counter < st.heard[0]) or st.last - counter <= REORDER_S * 1e6:
            raise WireError("replay", f"signer {who}: counter {counter} not after {st.last}")
        self._contest(st, f"a counter never heard {(st.last - counter) / 1e6:.2f} s behind the stream's last: "
                      "a second signer with the key")

    def _contest(self, st: _Stream, why: str) -> None:
        st.contest = why
        self.contests += 1
        raise WireError("contest", why)


def _trailer(attachment: bytes | None, trailer: struct.Struct, magic: bytes) -> tuple[bytes, int, bytes, bytes]:
    """(signer, counter, tag, inner attachment) of ``attachment``; raises ``unsigned``."""
    if attachment is None or len(attachment) < trailer.size:
        raise WireError("unsigned", "no authentication tag")
    got, signer, counter, tag = trailer.unpack_from(attachment, len(attachment) - trailer.size)
    if got != magic:
        raise WireError("unsigned", "no authentication tag" if got not in (MAGIC, MAGIC_ED25519)
                        else "a tag of the other kind of key")
    return signer, counter, tag, attachment[:-trailer.size]


class Verifier:
    """Checks the shared-key tags of one subscription's samples (not thread-safe: one callback
    thread, or the caller locks)."""

    def __init__(self, key: bytes, window_s: float = REPLAY_WINDOW_S) -> None:
        self._keyed = _keyed(key)
        self.streams = Streams(window_s)

    @property
    def window_us(self) -> int:
        return self.streams.window_us

    def _authentic(self, key_expr: str, payload: bytes, attachment: bytes | None) -> tuple[bytes, int, bytes]:
        signer, counter, mac, inner = _trailer(attachment, TRAILER, MAGIC)
        if not hmac.compare_digest(mac, _mac(self._keyed, key_expr, signer, counter, inner, payload)):
            raise WireError("signature", f"bad tag from signer {signer.hex()}")
        return signer, counter, inner

    def verify(self, key_expr: str, payload: bytes, attachment: bytes | None, now_us: int) -> tuple[str, bytes]:
        """(source ``"signer:<hex>"``, the attachment before the trailer) of an authentic, fresh
        sample; raises :class:`WireError` ``unsigned``, ``signature``, ``replay`` or ``contest``."""
        signer, counter, inner = self._authentic(key_expr, payload, attachment)
        self.streams.check(signer, counter, now_us)
        return SOURCE_PREFIX + signer.hex(), inner


class Ed25519Verifier(Verifier):
    """Checks that one subscription's samples were signed with the peer robot's private key
    (its ``public_key``; several: any one of them, as a team's carrier hears every passenger's
    clock pings on one key); the counter rules as :class:`Verifier`'s."""

    def __init__(self, public_key: Ed25519PublicKey | tuple[Ed25519PublicKey, ...],
                 window_s: float = REPLAY_WINDOW_S) -> None:
        self._publics = public_key if isinstance(public_key, tuple) else (public_key,)
        if not self._publics:
            raise ValueError("an Ed25519 verifier needs at least one public key")
        self.streams = Streams(window_s)

    def _authentic(self, key_expr: str, payload: bytes, attachment: bytes | None) -> tuple[bytes, int, bytes]:
        signer, counter, signature, inner = _trailer(attachment, ED25519_TRAILER, MAGIC_ED25519)
        signed = _signed_head(key_expr, signer, counter, inner) + payload
        for public in self._publics:
            try:
                public.verify(signature, signed)
            except InvalidSignature:
                continue
            return signer, counter, inner
        raise WireError("signature", f"bad signature from signer {signer.hex()}")
