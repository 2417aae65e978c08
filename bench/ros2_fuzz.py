"""Fuzz the ROS 2 carrier's inputs: ``marsupial carrier --backend ros2`` (rmw_zenoh keys) takes
``count`` odometry samples with random or mutated payloads and attachments, then valid ones.

    python -m bench.ros2_fuzz [--count 10000] [--seed 1]

The carrier runs as its own process, as in a flight; this one publishes on its odometry key over
Zenoh on loopback. Attachments: the six bytes ``ff ff ff ff ff 0f`` (which once made zenoh's
deserializer ask for 549,755,813,887 bytes and abort the process), random bytes of 0-80 bytes,
rmw_zenoh attachments of both forms with 1-3 bytes changed, or none; payloads: random bytes of
0-800 bytes or a valid Odometry with one byte changed. Then valid samples until the carrier
reports one (its summary). Passes when the carrier is alive after all of them, exits 0 on
SIGTERM, and its summary counts the dropped samples. Prints a table and exits non-zero on a
crash.
"""
from __future__ import annotations

import json
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import click
import numpy as np

from mission.bus.ros2 import encode_odometry_cdr, encode_rmw_attachment
from mission.bus.wire import CarrierState, decode_carrier_json
from sim.net import free_port, wait_for
from tests.support.zenoh_util import endpoint, peer, wait_matched

SIX_BYTES = b"\xff\xff\xff\xff\xff\x0f"
LAST_NED_M = np.array([7.0, 8.0, 0.0])
KEY = "0/fuzz/odom/nav_msgs::msg::dds_::Odometry_/RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"


def sample(rng: random.Random, good: bytes) -> tuple[bytes, bytes | None]:
    """One fuzzed (payload, attachment)."""
    pick = rng.random()
    attachment: bytes | None
    if pick < 0.1:
        attachment = SIX_BYTES
    elif pick < 0.4:
        attachment = rng.randbytes(rng.randrange(0, 81))
    elif pick < 0.7:
        mutated = bytearray(encode_rmw_attachment(rng.randrange(1, 1 << 40), time.time_ns(), rng.randbytes(16),
                                                  rng.choice(["current", "legacy"])))
        for _ in range(rng.randrange(1, 4)):
            mutated[rng.randrange(len(mutated))] = rng.randrange(256)
        attachment = bytes(mutated)
    else:
        attachment = None
    if rng.random() < 0.5:
        return rng.randbytes(rng.randrange(0, 801)), attachment
    payload = bytearray(good)
    payload[rng.randrange(len(payload))] = rng.randrange(256)
    return bytes(payload), attachment


@click.command()
@click.option("--count", type=click.IntRange(1), default=10_000, show_default=True)
@click.option("--seed", type=int, default=1, show_default=True)
def main(count: int, seed: int) -> None:
    rng = random.Random(seed)
    good = encode_odometry_cdr(CarrierState(1.0, 0, "local_ned", np.array([1.0, 2.0, 0.0]), np.zeros(3), 0.5))
    last = encode_odometry_cdr(CarrierState(2.0, 1, "local_ned", LAST_NED_M, np.zeros(3), 0.5))
    ep = endpoint(free_port())
    with tempfile.TemporaryDirectory(prefix="marsupial-ros2-fuzz-") as folder:
        summary = Path(folder) / "carrier.json"
        carrier = subprocess.Popen([sys.executable, "-m", "mission.cli", "carrier", "configs/demo.toml", "--pair", "fuzz",
                                    "--backend", "ros2", "--key-form", "rmw_zenoh", "--ros2-namespace", "fuzz",
                                    "--kinematics", "diff_drive", "--zenoh-listen", ep, "--summary", str(summary)],
                                   stderr=subprocess.DEVNULL)
        session = None
        try:
            session = peer(connect=[ep])
            pub = session.declare_publisher(KEY)
            wait_matched(pub, 30.0)
            t0 = time.monotonic()
            for _ in range(count):
                payload, attachment = sample(rng, good)
                pub.put(payload, attachment=attachment)
            elapsed = time.monotonic() - t0
            heard: list[CarrierState] = []
            states = session.declare_subscriber("marsupial/fuzz/carrier/state",
                                                lambda s: heard.append(decode_carrier_json(s.payload.to_bytes())))

            def taken() -> bool:  # valid ones after the fuzz, until the carrier publishes their position
                pub.put(last, attachment=encode_rmw_attachment(count + 1, time.time_ns(), bytes(16)))
                return carrier.poll() is not None or any(np.allclose(h.position, LAST_NED_M) for h in heard[-5:])

            wait_for(taken, 60.0, "the carrier's state at the valid odometry's position")
            states.undeclare()
            alive = carrier.poll() is None
            carrier.send_signal(signal.SIGTERM)
            rc = carrier.wait(30)
        finally:
            if carrier.poll() is None:
                carrier.kill()
                carrier.wait()
            if session is not None:
                session.close()
        report = json.loads(summary.read_text()).get("ros2", {}) if summary.exists() else {}
    dropped = report.get("dropped", {})
    print(f"| samples | put in [s] | alive after | exit code | dropped (by reason) |\n|---|---|---|---|---|\n"
          f"| {count} | {elapsed:.1f} | {alive} | {rc} | {dropped} |")
    sys.exit(0 if alive and rc == 0 and sum(dropped.values()) > 0 else 1)


if __name__ == "__main__":
    main()
