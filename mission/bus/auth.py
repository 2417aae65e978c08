"""Signing and verifying samples on Zenoh (thin I/O over :mod:`mission.bus.signing`).

:func:`bus_auth` reads the keys once: this robot's Ed25519 private key and its peer's public key
(``zenoh.private_key_file``, ``zenoh.peer_public_key_file``: one key per robot), else the pair's
shared key (``zenoh.signing_key_file``). Each publisher takes a :meth:`BusAuth.signer` (a stream
of its own) and each subscription a :meth:`BusAuth.verifier`. The counters are wall-clock
microseconds since the Unix epoch (``time.time_ns``), as MAVLink 2 signing's timestamps are:
shared between machines, unlike the injected (possibly lockstep) clock.
"""
from __future__ import annotations

import threading
import time

import zenoh
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from mission.bus.signing import Ed25519Signer, Ed25519Verifier, Signer, Verifier, pair_key
from mission.config.keys import read_key_file, read_private_key_file, read_public_key_file
from mission.config.schema import ZenohSection
from mission.errors import ConfigError

KEY_FIELD = "zenoh.signing_key_file"
PRIVATE_KEY_FIELD = "zenoh.private_key_file"
PEER_KEY_FIELD = "zenoh.peer_public_key_file"


def _now_us() -> int:
    return time.time_ns() // 1000


class SampleSigner:
    """Signs the samples one publisher puts (thread-safe); ``key``: the pair's shared key, or
    this robot's Ed25519 private key."""

    def __init__(self, key: bytes | Ed25519PrivateKey) -> None:
        self._signer = Ed25519Signer(key) if isinstance(key, Ed25519PrivateKey) else Signer(key)
        self._lock = threading.Lock()

    @property
    def source(self) -> str:
        return self._signer.source

    def attachment(self, key_expr: str, payload: bytes, inner: bytes = b"") -> bytes:
        """The attachment to put with ``payload`` on ``key_expr`` (``inner``: the sample's own)."""
        with self._lock:
            return self._signer.attachment(key_expr, payload, _now_us(), inner)


class SampleVerifier:
    """Verifies one subscription's samples (thread-safe); ``key``: the pair's shared key, or the
    peer robot's Ed25519 public key."""

    def __init__(self, key: bytes | Ed25519PublicKey) -> None:
        self._verifier = Ed25519Verifier(key) if isinstance(key, Ed25519PublicKey) else Verifier(key)
        self._lock = threading.Lock()

    def verify(self, sample: zenoh.Sample, payload: bytes) -> tuple[str, bytes]:
        """(source ``"signer:<hex>"``, the sample's own attachment) of ``sample`` whose payload
        bytes are ``payload``; raises :class:`~mission.bus.wire.WireError` (unsigned, signature,
        replay, contest)."""
        attachment = None if sample.attachment is None else sample.attachment.to_bytes()
        with self._lock:
            return self._verifier.verify(str(sample.key_expr), payload, attachment, _now_us())


class BusAuth:
    """The keys one robot signs and verifies a pair's samples with: the pair's shared key
    (:func:`mission.bus.signing.pair_key`; ``BusAuth(key, pair)``), or one key per robot
    (:meth:`per_robot`)."""

    def __init__(self, key: bytes, pair: str) -> None:
        shared = pair_key(key, pair)
        self._own: bytes | Ed25519PrivateKey = shared
        self._peer: bytes | Ed25519PublicKey = shared

    @classmethod
    def per_robot(cls, private_key: Ed25519PrivateKey, peer_public_key: Ed25519PublicKey) -> BusAuth:
        """Sign with this robot's ``private_key``; accept only what ``peer_public_key`` verifies."""
        auth = cls.__new__(cls)
        auth._own, auth._peer = private_key, peer_public_key
        return auth

    @property
    def mode(self) -> str:
        """``"ed25519"`` (one key per robot) or ``"shared"`` (one key for the pair)."""
        return "ed25519" if isinstance(self._own, Ed25519PrivateKey) else "shared"

    def signer(self) -> SampleSigner:
        return SampleSigner(self._own)

    def verifier(self) -> SampleVerifier:
        return SampleVerifier(self._peer)

    def own_verifier(self) -> SampleVerifier:
        """A verifier of what this robot's own key signed: its other nodes' samples (the
        passenger's camera node beside its autopilot), by its public key or the shared key."""
        own = self._own
        return SampleVerifier(own.public_key() if isinstance(own, Ed25519PrivateKey) else own)


def bus_auth(section: ZenohSection, pair: str | None = None, *, robot_link: bool = False) -> BusAuth | None:
    """How a robot signs a pair's bus per ``section``: with ``zenoh.private_key_file`` and
    ``zenoh.peer_public_key_file`` one key per robot, else the shared ``zenoh.signing_key_file``,
    else None (unsigned). ``robot_link``: the link between the carrier's controller and its own
    ROS-2-shaped robot, which knows only the shared key. Raises
    :class:`~mission.errors.ConfigError` naming the field when a file is unreadable or not a key."""
    if not robot_link and section.private_key_file and section.peer_public_key_file:
        return BusAuth.per_robot(read_private_key_file(section.private_key_file, PRIVATE_KEY_FIELD),
                                 read_public_key_file(section.peer_public_key_file, PEER_KEY_FIELD))
    if not section.signing_key_file:
        return None
    return BusAuth(read_key_file(section.signing_key_file, KEY_FIELD), pair or section.pair)


def check_team_auth(section: ZenohSection, auth: BusAuth | None, passengers: int) -> None:
    """Refuse one key per robot on the bus of a team of several ``passengers``
    (:class:`~mission.errors.ConfigError` naming ``zenoh.peer_public_key_file``): it names one peer,
    and every robot of a team hears several. A team signs with the pair's key (``zenoh.signing_key_file``)."""
    if auth is not None and auth.mode == "ed25519" and passengers > 1:
        raise ConfigError(PEER_KEY_FIELD, section.peer_public_key_file,
                          f"one peer key for a team of {passengers} passengers: sign the team's bus with the pair's key "
                          "(zenoh.signing_key_file); one public key per passenger is not built (docs/team.md)")


def unsigned_warning(section: ZenohSection) -> str | None:
    """The line ``run``, ``carrier`` and ``demo`` say at start-up when the pair's bus per
    ``section`` is unsigned (None when it is signed): what anyone on the network can then do."""
    if (section.private_key_file and section.peer_public_key_file) or section.signing_key_file:
        return None
    return (f"WARNING: the bus of pair {section.pair} is unsigned (no zenoh.private_key_file and "
            "zenoh.peer_public_key_file): anyone on its Zenoh network can pose as the carrier or the passenger, and "
            "a rogue that speaks before the real passenger takes the carrier's passenger binding (docs/security.md)")
