"""The one-command demo, end to end: separate processes over real UDP and Zenoh, in lockstep on
the mock vehicle's simulated time (the default) and in real time (``--realtime``)."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from mission.config.schema import load_config
from sim.batch.closed_loop import simulate_config
from tests.conftest import CONFIGS

DEMO = CONFIGS / "demo.toml"

pytestmark = pytest.mark.slow


def _demo(tmp_path, *args: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "mission.cli", "demo", "--log-root", str(tmp_path / "logs"),
           "--plot", str(tmp_path / "flight.png"), "--timeout", "90", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=150)


def _numbers(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


@pytest.fixture(scope="module")
def demo_flight(tmp_path_factory):
    """One plain demo (one pair, lockstep, with its plot), shared by the tests that read its
    outcome: the folder it flew in and the finished process."""
    root = tmp_path_factory.mktemp("demo")
    return root, _demo(root)


def test_two_lockstep_runs_give_the_same_flight(tmp_path, demo_flight):
    """Same configuration, same seed: the same summary to 1e-9 and the same flight record, tick for
    tick, whatever the machine's load (every participant waits for the others' stamped step). The
    second run is the shared demo flight (the plot is drawn after the flight, from its log)."""
    out = _demo(tmp_path / "a", "--plot", "")
    assert out.returncode == 0, out.stdout + out.stderr
    shared, shared_out = demo_flight
    assert shared_out.returncode == 0, shared_out.stdout + shared_out.stderr
    runs = [tmp_path / "a" / "logs" / "pair0", shared / "logs" / "pair0"]
    a, b = (json.loads((d / "summary.json").read_text()) for d in runs)
    for summary in (a, b):
        summary.get("carrier_feed", {}).pop("bound_source", None)  # a Zenoh session id: new in every run
        for counter in ("rx_bytes", "rx_messages", "rx_ignored", "tx_messages", "tx_heartbeats"):  # + the handshake
            summary.get("link", {}).pop(counter, None)
    assert a["ticks"] > 500 and a["phase"] == "DONE" and a["p1"] and a["p2"] and a["p3"]
    for summary in (a, b):  # every step in step: no participant dropped as silent, no fall-back, no sample lost
        lock = summary["lockstep"]
        assert lock["fallback"] is None and lock["downstream_dropped"] == 0 and lock["samples_lost"] == 0, lock
    assert {k: v for k, v in a.items() if k not in _numbers(a)} == {k: v for k, v in b.items() if k not in _numbers(b)}
    assert _numbers(a).keys() == _numbers(b).keys()
    for key, value in _numbers(a).items():
        assert b[key] == pytest.approx(value, abs=1e-9), key
    assert (runs[0] / "record.csv").read_text() == (runs[1] / "record.csv").read_text()


def test_demo_flies_p1_p3_with_plot(demo_flight):
    """The demo holds P1-P3 on the PX4-like mock (the tracking loop that holds the dock on PX4)."""
    tmp_path, out = demo_flight
    s = json.loads((tmp_path / "logs" / "pair0" / "summary.json").read_text())
    assert s["p1"] and s["p2"] and s["p3"] and s["phase"] == "DONE", s
    assert out.returncode == 0, out.stdout + out.stderr
    assert s["max_offset_before_separation_m"] <= 0.35
    assert s["relative_input_jump_m_s"] <= 0.05
    assert s["carrier_target_distance_at_separation_m"] == pytest.approx(8.0, abs=0.01)
    assert (tmp_path / "flight.png").stat().st_size > 20_000
    assert "P1-P3 held" in out.stdout + out.stderr
    assert (tmp_path / "logs" / "pair0" / "flight.tlog").stat().st_size > 10_000
    # `simulate` of the same mission config models what was flown: same verdict, same separation
    sim = simulate_config(load_config(DEMO)).summary()
    assert (sim["p1"], sim["p2"], sim["p3"]) == (s["p1"], s["p2"], s["p3"])
    assert sim["separation_time_s"] == pytest.approx(s["separation_time_s"], abs=0.5)
    assert sim["carrier_target_distance_at_separation_m"] == pytest.approx(s["carrier_target_distance_at_separation_m"], abs=0.01)


def test_three_pairs_fly_at_once_on_one_network(tmp_path):
    out = _demo(tmp_path, "--pairs", "3")
    for i in range(3):
        d = tmp_path / "logs" / f"pair{i}"
        s = json.loads((d / "summary.json").read_text())
        assert s["p1"] and s["p2"] and s["p3"] and s["phase"] == "DONE", (i, s)
        info = json.loads((d / "mission.json").read_text())
        assert info["pair"] == f"pair{i}"
        assert info["anchor_ned_m"] is not None
    assert out.returncode == 0, out.stdout + out.stderr
    # Crosstalk on the bus itself is tested in test_bridge_pairs.py (distinct states per pair);
    # here three full stacks share one Zenoh router and every one of them completes.


@pytest.mark.parametrize("carrier", ["mavlink", "ros2"])
def test_demo_with_a_real_carrier_interface_holds_p1_p3_and_the_guard(tmp_path, carrier):
    """--carrier mavlink: the carrier controller flies a mock PX4 Ackermann rover (sysid 2) in
    OFFBOARD; --carrier ros2: it drives a ROS-2-shaped diff-drive robot on rmw_zenoh keys. Each
    robot steps on the carrier's lockstep clock."""
    out = _demo(tmp_path, "--carrier", carrier)
    s = json.loads((tmp_path / "logs" / "pair0" / "summary.json").read_text())
    assert s["p1"] and s["p2"] and s["p3"] and s["phase"] == "DONE", s
    assert out.returncode == 0, out.stdout + out.stderr
    c = json.loads((tmp_path / "logs" / "pair0" / "carrier.json").read_text())
    assert c["backend"] == carrier and c["mode"] == "separated"
    assert c["closest_target_distance_m"] >= 8.0 - 0.5  # b c - p3_margin_m: the carrier's own guard
    assert 0.0 < c["braking_distance_m"] < 3.0
    # the robot stepped on the carrier's clock to the end of the flight
    assert c["lockstep"]["barriers"] > 500 and c["lockstep"]["downstream_dropped"] == 0, c["lockstep"]
    assert c["lockstep"]["fallback"] is None and s["lockstep"]["fallback"] is None, (c["lockstep"], s["lockstep"])
