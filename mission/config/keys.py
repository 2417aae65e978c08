"""Key files: a 32-byte key as 64 hex digits or 32 raw bytes (MAVLink 2 signing, the bus's shared
key), and a robot's Ed25519 keys (its private key, its peer's public key; PEM or 32 bytes)."""
from __future__ import annotations

import os
from pathlib import Path

from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

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


def _key_bytes(path: str | os.PathLike[str], field: str) -> bytes:
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise ConfigError(field, str(path), f"cannot read the key file: {exc.strerror}") from None


def read_private_key_file(path: str | os.PathLike[str], field: str) -> Ed25519PrivateKey:
    """The Ed25519 private key of the file at ``path``: PEM (PKCS #8, unencrypted, e.g. ``openssl
    genpkey -algorithm ed25519``) or its 32-byte seed (64 hex digits or raw). Raises
    :class:`ConfigError` naming ``field``; the key never appears in the message."""
    raw = _key_bytes(path, field)
    if raw.lstrip().startswith(b"-----BEGIN"):
        try:
            key = serialization.load_pem_private_key(raw, password=None)
        except (ValueError, TypeError):
            raise ConfigError(field, str(path), "not an unencrypted PEM private key") from None
        if not isinstance(key, Ed25519PrivateKey):
            raise ConfigError(field, str(path), "not an Ed25519 private key")
        return key
    return Ed25519PrivateKey.from_private_bytes(read_key_file(path, field))


def read_public_key_file(path: str | os.PathLike[str], field: str) -> Ed25519PublicKey:
    """The Ed25519 public key of the file at ``path``: PEM (SubjectPublicKeyInfo, e.g. ``openssl
    pkey -pubout``) or its 32 bytes (64 hex digits or raw). Raises :class:`ConfigError` naming ``field``."""
    raw = _key_bytes(path, field)
    if raw.lstrip().startswith(b"-----BEGIN"):
        try:
            key = serialization.load_pem_public_key(raw)
        except ValueError:
            raise ConfigError(field, str(path), "not a PEM public key") from None
        if not isinstance(key, Ed25519PublicKey):
            raise ConfigError(field, str(path), "not an Ed25519 public key")
        return key
    try:
        return Ed25519PublicKey.from_public_bytes(read_key_file(path, field))
    except ValueError:
        raise ConfigError(field, str(path), "not an Ed25519 public key") from None


def write_key_pair(private_path: Path, public_path: Path) -> None:
    """A fresh Ed25519 key pair: the private key's seed (64 hex digits, mode 0600) at
    ``private_path`` and the public key (64 hex digits) at ``public_path``; neither may exist."""
    key = Ed25519PrivateKey.generate()
    seed = key.private_bytes(serialization.Encoding.Raw, serialization.PrivateFormat.Raw, serialization.NoEncryption())
    public = key.public_key().public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
    fd = os.open(private_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(seed.hex() + "\n")
    fd = os.open(public_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    with os.fdopen(fd, "w") as f:
        f.write(public.hex() + "\n")
