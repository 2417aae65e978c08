"""How well a pair's ``flight.mcap`` and ``carrier.mcap`` line up in time (their log times are
epoch nanoseconds, docs/flight-data.md).

    python -m bench.flight_epoch LOG_DIR [--pair pair0]

Each carrier state the mission used (``/<pair>/tf/carrier``: position, log time T) is matched
with the carrier's own step, while it moves faster than 0.5 m/s, that was nearest that position
(within :data:`MATCH_M`) (``/<pair>/carrier/status``, log time
T'); T - T' is the state's way over the bus plus the difference between the two files' clocks.
Prints the median, 5th and 95th percentiles [s] over the matched states, and the two files'
epochs. Run it on a real-time flight, e.g. ``marsupial demo --realtime --speed 1``.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import click
import numpy as np

from mission.flightdata.read import read_messages

MATCH_M = 0.02  # [m] a carrier step this close to the state the mission used is that state

def offsets(log_dir: Path, pair: str) -> tuple[np.ndarray, int, int]:
    """(T - T' [s] of each matched state, flight epoch [ns], carrier epoch [ns])."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    flight = read_messages(log_dir / "flight.mcap", set())  # its metadata (the epoch)
    carrier = read_messages(log_dir / "carrier.mcap", {f"/{pair}/carrier/status"})
    times, points = [], []
    for _, _, t, data in carrier.messages:
        status = json.loads(data)
        v = status.get("velocity")
        if status.get("published") and status.get("position") and v and np.hypot(v["n"], v["e"]) > 0.5:
            times.append(t)
            points.append([status["position"]["n"], status["position"]["e"]])
    track, stamps = np.array(points), np.array(times)
    out = []
    if track.size == 0:
        return np.array(out), flight.epoch_ns, carrier.epoch_ns
    with open(log_dir / "flight.mcap", "rb") as f:
        for _, _, msg, tf in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                topics=[f"/{pair}/tf/carrier"]):
            gap = np.hypot(track[:, 0] - tf.translation.x, track[:, 1] - tf.translation.y)
            i = int(np.argmin(gap))
            if gap[i] < MATCH_M:
                out.append((msg.log_time - int(stamps[i])) / 1e9)
    return np.array(out), flight.epoch_ns, carrier.epoch_ns


@click.command()
@click.argument("log_dir", type=click.Path(file_okay=False, exists=True))
@click.option("--pair", default="pair0", show_default=True)
def main(log_dir: str, pair: str) -> None:
    d, e_flight, e_carrier = offsets(Path(log_dir), pair)
    if d.size == 0:
        click.echo("no carrier state of the flight matched one the carrier published", err=True)
        sys.exit(1)
    p5, p50, p95 = np.percentile(d, [5, 50, 95])
    click.echo(f"| matched states | T - T' median [s] | p5 [s] | p95 [s] | epoch flight - carrier [s] |\n"
               f"|---|---|---|---|---|\n| {d.size} | {p50:.4f} | {p5:.4f} | {p95:.4f} | {(e_flight - e_carrier) / 1e9:.3f} |")


if __name__ == "__main__":
    main()
