"""Per-sample cost of the bus's codecs: decode + validate one message (prints a table).

    python -m bench.wire_bench [--samples 20000]

Each row times one call, ``samples`` times after a warm-up, and gives the median and p99 of the
thread's CPU time in microseconds (CPU time leaves out what the scheduler gave to other processes
on a loaded machine). Rows: a valid carrier state and passenger status in JSON (what a feed does
per sample at 30-50 Hz), a CDR Odometry, building a :class:`CarrierState` in code (what a
publisher does), and the rejection of hostile samples (NaN, a wrong type, 8 KB of nesting).
"signed" rows add the bus's authentication tag (:mod:`mission.bus.signing`): verify (the
signature, replay window, the signer's counter) then decode, what a signed feed does per sample;
signing, what a publisher adds; and refusing an unsigned or forged sample (before any
decoding). "Ed25519" rows: one key per robot (``zenoh.private_key_file``); the others: the
pair's shared key (``zenoh.signing_key_file``, a keyed BLAKE2b MAC).
"""
from __future__ import annotations

import json
import time
from typing import Callable

import click
import numpy as np

from mission.bus.wire import CarrierState, WireError, decode_carrier_json, decode_passenger_json, encode_passenger_json
from mission.bus.wire import PassengerStatus
from mission.bus.ros2 import decode_odometry_cdr, encode_odometry_cdr
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

from mission.bus.signing import Ed25519Signer, Ed25519Verifier, Signer, Verifier, pair_key

CARRIER = json.dumps({"stamp": 12.345, "seq": 7, "frame": "local_ned", "position": [1.0, 2.0, -3.0],
                      "velocity": [0.5, -0.25, 0.0], "yaw": 0.1}).encode()
PASSENGER = encode_passenger_json(PassengerStatus("RIDING", 3.2, 41, np.array([1.0, 2.0, -1.5]),
                                                  np.array([0.5, 0.0, 0.0]), False, None))
NAN = CARRIER.replace(b"2.0", b"NaN")
WRONG_TYPE = CARRIER.replace(b"7", b'"7"')
NESTED = b"[" * 4000 + b"]" * 4000
ODOMETRY = encode_odometry_cdr(CarrierState(12.345, 7, "local_ned", np.array([1.0, 2.0, -3.0]),
                                            np.array([0.5, -0.25, 0.0]), 0.1))


KEY_EXPR = "marsupial/pair0/carrier/state"
PAIR_KEY = pair_key(bytes(range(32)), "pair0")
NOW_US = 1_800_000_000_000_000
ROBOT_KEY = Ed25519PrivateKey.from_private_bytes(bytes(range(32)))


class _Signed:
    """Verify + decode of signed samples, each with a fresh counter (a replayed one is refused)."""

    def __init__(self, raw: bytes, decode: Callable[[bytes], object], ed25519: bool = False) -> None:
        self.raw, self.decode = raw, decode
        self.signer, self.verifier = ((Ed25519Signer(ROBOT_KEY), Ed25519Verifier(ROBOT_KEY.public_key())) if ed25519
                                      else (Signer(PAIR_KEY), Verifier(PAIR_KEY)))
        self.tags: list[bytes] = []

    def __call__(self) -> object:
        if not self.tags:  # signed ahead, on the first (warm-up, untimed) call: enough for a whole row
            self.tags = [self.signer.attachment(KEY_EXPR, self.raw, NOW_US) for _ in range(25_000)][::-1]
        self.verifier.verify(KEY_EXPR, self.raw, self.tags.pop(), NOW_US)
        return self.decode(self.raw)


def _refused(attachment: bytes | None, ed25519: bool = False) -> Callable[[], object]:
    verifier = Ed25519Verifier(ROBOT_KEY.public_key()) if ed25519 else Verifier(PAIR_KEY)

    def call() -> object:
        try:
            verifier.verify(KEY_EXPR, CARRIER, attachment, NOW_US)
        except WireError as exc:
            return exc.reason
        raise AssertionError("accepted an unsigned or forged sample")
    return call


_SIGNER = Signer(PAIR_KEY)
FORGED = bytearray(Signer(PAIR_KEY).attachment(KEY_EXPR, CARRIER, NOW_US))
FORGED[-1] ^= 1
_ROBOT_SIGNER = Ed25519Signer(ROBOT_KEY)
FORGED_ED25519 = bytearray(Ed25519Signer(ROBOT_KEY).attachment(KEY_EXPR, CARRIER, NOW_US))
FORGED_ED25519[-1] ^= 1


def _rejected(decode: Callable[[bytes], object], raw: bytes) -> Callable[[], object]:
    def call() -> object:
        try:
            decode(raw)
        except WireError as exc:
            return exc.reason
        raise AssertionError("accepted a hostile sample")
    return call


CASES: dict[str, Callable[[], object]] = {
    "carrier JSON": lambda: decode_carrier_json(CARRIER),
    "passenger JSON": lambda: decode_passenger_json(PASSENGER),
    "carrier CDR Odometry": lambda: decode_odometry_cdr(ODOMETRY, seq=1),
    "CarrierState(...) in code": lambda: CarrierState(12.345, 7, "local_ned", [1.0, 2.0, -3.0], [0.5, -0.25, 0.0], 0.1),
    "reject NaN (JSON)": _rejected(decode_carrier_json, NAN),
    "reject wrong type (JSON)": _rejected(decode_carrier_json, WRONG_TYPE),
    "reject 8 KB nesting (JSON)": _rejected(decode_carrier_json, NESTED),
    "carrier JSON, signed": _Signed(CARRIER, decode_carrier_json),
    "passenger JSON, signed": _Signed(PASSENGER, decode_passenger_json),
    "sign a carrier state": lambda: _SIGNER.attachment(KEY_EXPR, CARRIER, NOW_US),
    "reject unsigned": _refused(None),
    "reject forged tag": _refused(bytes(FORGED)),
    "carrier JSON, Ed25519": _Signed(CARRIER, decode_carrier_json, ed25519=True),
    "sign a state, Ed25519": lambda: _ROBOT_SIGNER.attachment(KEY_EXPR, CARRIER, NOW_US),
    "reject forged, Ed25519": _refused(bytes(FORGED_ED25519), ed25519=True),
}


def cpu_us(call: Callable[[], object], samples: int) -> tuple[float, float]:
    """Median and p99 [us] of the thread CPU time of ``call()``."""
    for _ in range(min(samples, 500)):
        call()
    cpu = np.empty(samples)
    for i in range(samples):
        c0 = time.thread_time_ns()
        call()
        cpu[i] = time.thread_time_ns() - c0
    return float(np.percentile(cpu, 50) / 1e3), float(np.percentile(cpu, 99) / 1e3)


def decode_costs(samples: int) -> list[dict]:
    """One ``{"message", "p50_us", "p99_us"}`` per row of :data:`CASES` (thread CPU)."""
    rows = []
    for name, call in CASES.items():
        p50, p99 = cpu_us(call, samples)
        rows.append({"message": name, "p50_us": p50, "p99_us": p99})
    return rows


@click.command()
@click.option("--samples", default=20000, show_default=True, help="calls timed per row")
def main(samples: int) -> None:
    """Print the table."""
    print(f"{'message':<28} {'p50 us':>8} {'p99 us':>8}")
    for name, call in CASES.items():
        p50, p99 = cpu_us(call, samples)
        print(f"{name:<28} {p50:8.2f} {p99:8.2f}", flush=True)


if __name__ == "__main__":
    main()
