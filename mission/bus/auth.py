"""Signing and verifying samples on Zenoh (thin I/O over :mod:`mission.bus.signing`).

:func:`bus_auth` reads the keys once: this robot's Ed25519 private key and its peer's public key
(``zenoh.private_key_file``, ``zenoh.peer_public_key_file``: one key per robot), else the pair's
shared key (``zenoh.signing_key_file``). Each publisher takes a :meth:`BusAuth.signer` (a stream
of its own) and each subscription a :meth:`BusAuth.verifier`. The counters are wall-clock
microseconds since the Unix epoch (``time.time_ns``), as MAVLink 2 signing's timestamps are:
shared between machines, unlike the injected (possibly lockstep) clock.
"""
from __future__ import annotations

import copy
import threading
import time
from collections.abc import Sequence
from pathlib import Path

import zenoh
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from mission.bus.signing import Ed25519Signer, Ed25519Verifier, Signer, Verifier, pair_key
from mission.config.keys import read_key_file, read_private_key_file, read_public_key_file
from mission.config.schema import ZenohSection
from mission.errors import ConfigError

KEY_FIELD = "zenoh.signing_key_file"
PRIVATE_KEY_FIELD = "zenoh.private_key_file"
PEER_KEY_FIELD = "zenoh.peer_public_key_file"
KEYS_DIR_FIELD = "zenoh.public_keys_dir"
CARRIER = "carrier"  #: the carrier's name in a team's key directory (``carrier.pub``)


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

    def __init__(self, key: bytes | Ed25519PublicKey | tuple[Ed25519PublicKey, ...]) -> None:
        self._verifier = Verifier(key) if isinstance(key, bytes) else Ed25519Verifier(key)
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
    (:meth:`per_robot`), a team's with each teammate's key by name (:meth:`for_peer`)."""

    def __init__(self, key: bytes, pair: str) -> None:
        shared = pair_key(key, pair)
        self._own: bytes | Ed25519PrivateKey = shared
        self._peer: bytes | Ed25519PublicKey | tuple[Ed25519PublicKey, ...] = shared
        self._peers: dict[str, Ed25519PublicKey] = {}

    @classmethod
    def per_robot(cls, private_key: Ed25519PrivateKey, peer_public_key: Ed25519PublicKey | tuple[Ed25519PublicKey, ...],
                  peers: dict[str, Ed25519PublicKey] | None = None) -> BusAuth:
        """Sign with this robot's ``private_key``; accept only what ``peer_public_key`` verifies
        (several: any of them); ``peers``: a team's robots' keys by name (:meth:`for_peer`)."""
        auth = cls.__new__(cls)
        auth._own, auth._peer, auth._peers = private_key, peer_public_key, dict(peers or {})
        return auth

    def for_peer(self, name: str) -> BusAuth:
        """This robot's keys for what robot ``name`` of a team signs (its status, its clock calls):
        only ``name``'s own key verifies it. Without a team's keys (the pair's shared key, or one
        peer): itself. Raises :class:`KeyError` for a name the team's keys do not hold."""
        if not self._peers:
            return self
        auth = copy.copy(self)
        auth._peer = self._peers[name]
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


def public_key_path(directory: str | Path, robot: str) -> Path:
    """The public key file of ``robot`` (a passenger's name, or :data:`CARRIER`) in a team's key
    directory ``directory``: ``<directory>/<robot>.pub``."""
    return Path(directory) / f"{robot}.pub"


def _raw(key: Ed25519PublicKey) -> bytes:
    return key.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)


def bus_auth(section: ZenohSection, pair: str | None = None, *, robot_link: bool = False) -> BusAuth | None:
    """How a robot signs a pair's bus per ``section``: with ``zenoh.private_key_file`` and
    ``zenoh.peer_public_key_file`` one key per robot; with ``zenoh.public_keys_dir`` a passenger of
    a team (its peer the carrier, ``carrier.pub``; its teammates: :func:`team_bus_auth`); else the
    shared ``zenoh.signing_key_file``, else None (unsigned). ``robot_link``: the link between the
    carrier's controller and its own ROS-2-shaped robot, which knows only the shared key. Raises
    :class:`~mission.errors.ConfigError` naming the field when a file is unreadable or not a key,
    or the key directory is given without this robot's own private key."""
    if not robot_link and section.public_keys_dir:
        return team_bus_auth(section, (), "", pair)
    if not robot_link and section.private_key_file and section.peer_public_key_file:
        return BusAuth.per_robot(read_private_key_file(section.private_key_file, PRIVATE_KEY_FIELD),
                                 read_public_key_file(section.peer_public_key_file, PEER_KEY_FIELD))
    if not section.signing_key_file:
        return None
    return BusAuth(read_key_file(section.signing_key_file, KEY_FIELD), pair or section.pair)


def team_bus_auth(section: ZenohSection, names: Sequence[str], me: str, pair: str | None = None) -> BusAuth | None:
    """How robot ``me`` (:data:`CARRIER`, or a passenger's name; "": a passenger, unnamed) of a team
    whose passengers are ``names`` signs the team's bus. With ``zenoh.public_keys_dir`` one key per
    robot: it signs with ``zenoh.private_key_file``, which must be the private half of
    ``<dir>/<me>.pub``; a passenger's peer is the carrier (``carrier.pub``), the carrier's any
    passenger (its clock echo), and :meth:`BusAuth.for_peer` gives each robot's own (``<name>.pub``).
    Without it: :func:`bus_auth`. Raises :class:`~mission.errors.ConfigError` naming the field: no
    private key, a key file missing or not a key, two robots on one key, a private key not ``me``'s."""
    directory = section.public_keys_dir
    if not directory:
        return bus_auth(section, pair)
    who = "the carrier" if me == CARRIER else f"passenger {me}" if me else "this passenger"
    if not section.private_key_file:
        raise ConfigError(PRIVATE_KEY_FIELD, None, f"the team's bus is signed one key per robot ({KEYS_DIR_FIELD}): "
                          f"{who} signs with its own private key (--zenoh-private-key FILE)")
    if CARRIER in names:
        raise ConfigError("team.passengers", list(names), f"a passenger may not be named {CARRIER!r} with "
                          f"{KEYS_DIR_FIELD}: {CARRIER}.pub is the carrier's key")
    private = read_private_key_file(section.private_key_file, PRIVATE_KEY_FIELD)
    robots = [CARRIER, *names]
    keys = {robot: read_public_key_file(public_key_path(directory, robot), KEYS_DIR_FIELD) for robot in robots}
    seen: dict[bytes, str] = {}
    for robot, key in keys.items():
        if (other := seen.setdefault(_raw(key), robot)) != robot:
            raise ConfigError(KEYS_DIR_FIELD, directory, f"{other}.pub and {robot}.pub hold the same key: each robot "
                              "needs its own, or either can sign as the other")
    if me and _raw(private.public_key()) != _raw(keys[me]):
        raise ConfigError(PRIVATE_KEY_FIELD, section.private_key_file,
                          f"not {who}'s key: its public half is not {public_key_path(directory, me)}")
    peer = tuple(keys[n] for n in names) if me == CARRIER else keys[CARRIER]
    return BusAuth.per_robot(private, peer, {robot: key for robot, key in keys.items() if robot != me})


def check_team_auth(section: ZenohSection, passengers: int) -> None:
    """Refuse a single peer's key on the bus of a team of several ``passengers``
    (:class:`~mission.errors.ConfigError` naming ``zenoh.peer_public_key_file``): it names one peer,
    and every robot of a team hears several; a team names every robot's key in a directory
    (``zenoh.public_keys_dir``), and a key directory needs a team of several."""
    if section.peer_public_key_file and passengers > 1:
        raise ConfigError(PEER_KEY_FIELD, section.peer_public_key_file,
                          f"one peer key for a team of {passengers} passengers: give every robot's public key in "
                          f"{KEYS_DIR_FIELD} (carrier.pub, <passenger>.pub; docs/team.md), or sign with the pair's "
                          "key (zenoh.signing_key_file)")
    if section.public_keys_dir and passengers < 2:
        raise ConfigError(KEYS_DIR_FIELD, section.public_keys_dir,
                          "a team's key directory: a file of one passenger names its peer's key in "
                          f"{PEER_KEY_FIELD}")


def unsigned_warning(section: ZenohSection) -> str | None:
    """The line ``run``, ``carrier`` and ``demo`` say at start-up when the pair's bus per
    ``section`` is unsigned (None when it is signed): what anyone on the network can then do."""
    if (section.private_key_file and section.peer_public_key_file) or section.public_keys_dir or section.signing_key_file:
        return None
    return (f"WARNING: the bus of pair {section.pair} is unsigned (no zenoh.private_key_file and "
            "zenoh.peer_public_key_file): anyone on its Zenoh network can pose as the carrier or the passenger, and "
            "a rogue that speaks before the real passenger takes the carrier's passenger binding (docs/security.md)")
