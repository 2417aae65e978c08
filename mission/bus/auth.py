"""Signing and verifying samples on Zenoh (thin I/O over :mod:`mission.bus.signing`).

:func:`bus_auth` reads ``zenoh.signing_key_file`` once; each publisher takes a
:meth:`BusAuth.signer` (an identity of its own) and each subscription a :meth:`BusAuth.verifier`.
The counters are wall-clock microseconds since the Unix epoch (``time.time_ns``), as MAVLink 2
signing's timestamps are: shared between machines, unlike the injected (possibly lockstep) clock.
"""
from __future__ import annotations

import threading
import time

import zenoh

from mission.bus.signing import Signer, Verifier, pair_key
from mission.config.keys import read_key_file
from mission.config.schema import ZenohSection

KEY_FIELD = "zenoh.signing_key_file"


def _now_us() -> int:
    return time.time_ns() // 1000


class SampleSigner:
    """Signs the samples one publisher puts (thread-safe)."""

    def __init__(self, key: bytes) -> None:
        self._signer = Signer(key)
        self._lock = threading.Lock()

    @property
    def source(self) -> str:
        return self._signer.source

    def attachment(self, key_expr: str, payload: bytes, inner: bytes = b"") -> bytes:
        """The attachment to put with ``payload`` on ``key_expr`` (``inner``: the sample's own)."""
        with self._lock:
            return self._signer.attachment(key_expr, payload, _now_us(), inner)


class SampleVerifier:
    """Verifies one subscription's samples (thread-safe)."""

    def __init__(self, key: bytes) -> None:
        self._verifier = Verifier(key)
        self._lock = threading.Lock()

    def verify(self, sample: zenoh.Sample, payload: bytes) -> tuple[str, bytes]:
        """(source ``"signer:<hex>"``, the sample's own attachment) of ``sample`` whose payload
        bytes are ``payload``; raises :class:`~mission.bus.wire.WireError` (unsigned, signature,
        replay)."""
        attachment = None if sample.attachment is None else sample.attachment.to_bytes()
        with self._lock:
            return self._verifier.verify(str(sample.key_expr), payload, attachment, _now_us())


class BusAuth:
    """The signing key of one pair (:func:`mission.bus.signing.pair_key`)."""

    def __init__(self, key: bytes, pair: str) -> None:
        self._key = pair_key(key, pair)

    def signer(self) -> SampleSigner:
        return SampleSigner(self._key)

    def verifier(self) -> SampleVerifier:
        return SampleVerifier(self._key)


def bus_auth(section: ZenohSection, pair: str | None = None) -> BusAuth | None:
    """The pair's signing key per ``section.signing_key_file`` (None: unsigned). Raises
    :class:`~mission.errors.ConfigError` naming the field when the file is unreadable or not a key."""
    if not section.signing_key_file:
        return None
    return BusAuth(read_key_file(section.signing_key_file, KEY_FIELD), pair or section.pair)
