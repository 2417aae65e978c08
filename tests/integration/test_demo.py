"""The one-command demo, end to end: separate processes over real UDP and Zenoh, in lockstep on
the mock vehicle's simulated time (the default) and in real time (``--realtime``); several pairs
at once, and the live view (``--live``) of each while it flies."""
from __future__ import annotations

import json
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from mission.config.schema import load_config
from mission.record.table import read_record
from sim.batch.closed_loop import simulate_config
from sim.net import stop_process, wait_for
from sim.testing.foxglove_viewer import LiveViewer
from tests.conftest import CONFIGS, free_port

DEMO = CONFIGS / "demo.toml"

pytestmark = pytest.mark.slow

# A class per flight (or per flights that share one): `--dist loadscope` schedules a class as its own
# unit, so the module's demo flights spread over the workers instead of queueing on one.


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


def free_ports_in_a_row(n: int) -> int:
    """A free TCP port p on 127.0.0.1 whose n - 1 neighbours above it are free too (pair i serves on p + i)."""
    for _ in range(200):
        ports = [free_port() for _ in range(n)]
        if ports == list(range(ports[0], ports[0] + n)):
            return ports[0]
    raise AssertionError(f"no {n} neighbouring free ports")


@dataclass
class LiveFlight:
    """The three-pair demo as it flew: its folder, exit code and output (stdout and stderr), the
    first port of its live views, the viewers of pairs 0 and 1, and whether both viewers saw their
    pair's pose and a flying phase before the demo ended (None) or why not."""
    root: Path
    code: int | None
    text: str
    port: int
    viewers: tuple[LiveViewer, LiveViewer]
    not_seen_flying: str | None


@pytest.fixture(scope="module")
def three_pairs(tmp_path_factory) -> LiveFlight:
    """Three pairs at once on one network (``--pairs 3``), each serving its flight live (``--live``:
    pair i on port + i), pairs 0 and 1 watched by a Foxglove viewer while they fly; no plot (the
    one-pair plot is :func:`demo_flight`'s). Pair 0 is the plain demo's configuration and seed (pair
    i's vehicle draws from seed i): the second run of the determinism check."""
    root = tmp_path_factory.mktemp("pairs")
    port = free_ports_in_a_row(3)
    cmd = [sys.executable, "-m", "mission.cli", "demo", "--pairs", "3", "--live", f"127.0.0.1:{port}",
           "--log-root", str(root / "logs"), "--plot", "", "--timeout", "90"]
    not_seen, code = None, None
    with open(root / "demo.out", "w") as out:
        demo = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, text=True)
        try:
            viewers = [LiveViewer(f"ws://127.0.0.1:{port + i}", topics={f"/pair{i}/phase", f"/pair{i}/tf/passenger"},
                                  connect_timeout_s=60.0) for i in range(2)]
            with viewers[0] as v0, viewers[1] as v1:
                # the pose and the phase arrive while the pair flies (before the demo has ended)
                try:
                    wait_for(lambda: _flying_seen(v0, "pair0") and _flying_seen(v1, "pair1") and demo.poll() is None,
                             90.0, "poses and a flying phase from both pairs while they fly")
                except AssertionError as e:
                    not_seen = str(e)
                code = demo.wait(timeout=150)
        finally:
            stop_process(demo, 30.0)
    text = (root / "demo.out").read_text()
    if code != 0 or not_seen:  # what each child logged (the demo writes it beside the pair's flight)
        text += "".join(f"\n--- {log} (last 40 lines)\n" + "".join(log.read_text().splitlines(True)[-40:])
                        for log in sorted((root / "logs").glob("pair*/*.log")))
    return LiveFlight(root, code, text, port, (v0, v1), not_seen)


def _flying_seen(v: LiveViewer, pair: str) -> bool:
    time.sleep(0.05)  # (polled: leave the viewers' threads the time to receive)
    phases = v.messages(f"/{pair}/phase")[-3:]
    return bool(v.messages(f"/{pair}/tf/passenger")) and any(
        v.decode(f"/{pair}/phase", p)["phase"] in ("JOIN", "RIDING", "SEPARATED", "NAVIGATING") for _, p, _ in phases)


# The plain demo and the three pairs (its second run, the live view) are one unit: the determinism check
# reads both.
@pytest.mark.timeout(300)
class TestTheDemoFlight:
    def test_two_lockstep_runs_give_the_same_flight(self, demo_flight, three_pairs):
        """Same configuration, same seed: the same summary to 1e-9 and the same flight record, tick for
        tick, whatever the machine's load (every participant waits for the others' stamped step). The
        second run is pair 0 of the three-pair demo (:func:`three_pairs`: the same configuration and
        seed, flown beside two other pairs on one network and served live). On the mock's default
        estimate errors (PX4 SITL's, seed 0): the vehicle's first barrier carried step 0's streams,
        which a mission bound in time read and a later one did not, so two runs differed from their
        first row (the vehicle at 0.0 against 0.065 m north at t = 0.02 s); before any answer the
        vehicle now sends only its hello (sim/vehicle/lockstep.py)."""
        # the first run is the class's plain demo (its plot is drawn after the flight, from its files)
        root, out = demo_flight
        assert out.returncode == 0, out.stdout + out.stderr
        assert three_pairs.code == 0, three_pairs.text
        runs = [root / "logs" / "pair0", three_pairs.root / "logs" / "pair0"]
        a, b = (json.loads((d / "summary.json").read_text()) for d in runs)
        for summary in (a, b):
            summary.get("carrier_feed", {}).pop("bound_source", None)  # a Zenoh session id: new in every run
            # + the handshake; tx_commands counts the home updates (below)
            for counter in ("rx_bytes", "rx_messages", "rx_ignored", "tx_messages", "tx_heartbeats", "tx_commands"):
                summary.get("link", {}).pop(counter, None)
            # how many barrier rounds the processes' start took, and the PX4 home updates sent at most
            # once a wall second from the command thread: how the run went, not the flight
            summary.get("lockstep", {}).pop("barriers", None)
            summary.pop("home", None)
            for counter in ("read", "unread"):  # the failsafe parameters read back by the same thread, as often
                summary.get("px4_kept", {}).pop(counter, None)
        assert a["ticks"] > 500 and a["phase"] == "DONE" and a["p1"] and a["p2"] and a["p3"]
        for summary in (a, b):  # every step in step: no participant dropped as silent, no fall-back, no sample lost
            lock = summary["lockstep"]
            assert lock["fallback"] is None and lock["downstream_dropped"] == 0 and lock["samples_lost"] == 0, lock
        assert {k: v for k, v in a.items() if k not in _numbers(a)} == {k: v for k, v in b.items() if k not in _numbers(b)}
        assert _numbers(a).keys() == _numbers(b).keys()
        for key, value in _numbers(a).items():
            assert b[key] == pytest.approx(value, abs=1e-9), key
        assert (runs[0] / "record.csv").read_text() == (runs[1] / "record.csv").read_text()

    def test_demo_flies_p1_p3_with_plot(self, demo_flight):
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

    def test_demo_flight_mcap_reads_back_with_foxglove_schemas(self, demo_flight):
        """logs/demo/pair0/flight.mcap, read with the mcap package (Foxglove's protobuf messages
        decoded from the schemas in the file): the Foxglove schemas, messages spanning the record,
        the phase changes in order, the clock it is on; and the carrier's own carrier.mcap."""
        root, out = demo_flight
        d = root / "logs" / "pair0"
        rec = read_record(d)
        with open(d / "flight.mcap", "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            summary = reader.get_summary()
            assert summary is not None
            schemas = {summary.schemas[c.schema_id].name for c in summary.channels.values()}
            logs = [m.message for *_, m in reader.iter_decoded_messages(topics=["/pair0/log"])]
            last_tf = [m for *_, m in reader.iter_decoded_messages(topics=["/pair0/tf/passenger"])][-1]
            scene = [m for *_, m in reader.iter_decoded_messages(topics=["/pair0/scene"])][-1]
            metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        assert len(summary.channels) >= 8, sorted(c.topic for c in summary.channels.values())
        assert {"foxglove.FrameTransform", "foxglove.SceneUpdate", "foxglove.Log"} <= schemas
        stats = summary.statistics
        assert stats is not None
        epoch = int(metadata["clock"]["epoch_ns"])  # log times are epoch ns: the demo's epoch + the mission clock
        assert epoch > 1.5e18
        assert (stats.message_start_time - epoch) / 1e9 == pytest.approx(rec.t[0], abs=0.1)
        assert (stats.message_end_time - epoch) / 1e9 == pytest.approx(rec.t[-1], abs=0.1)
        changes = [str(p) for i, p in enumerate(rec.phase) if i == 0 or p != rec.phase[i - 1]]
        assert [text.split()[1] for text in logs if text.startswith("phase ")] == changes
        assert changes[:1] == ["PREFLIGHT"] and changes[-3:] == ["ARRIVED", "HOLD", "DONE"] and "SEPARATED" in changes
        assert metadata["clock"]["clock"] == "mission" and metadata["clock"]["source"].startswith("lockstep")
        # the last passenger pose is the record's last position, at the record's last time
        x_p = rec.vec("x_p")[-1]
        assert (last_tf.translation.x, last_tf.translation.y, last_tf.translation.z) == pytest.approx(tuple(x_p))
        assert (last_tf.timestamp.seconds * 10**9 + last_tf.timestamp.nanos - epoch) / 1e9 == pytest.approx(rec.t[-1], abs=1e-6)
        assert {"target", "bc_circle", "carrier", "passenger", "dock", "anchor"} <= {e.id for e in scene.entities}
        # marsupial plot reads the MCAP as it reads the CSV: the same record
        from_mcap = read_record(d / "flight.mcap")
        assert (from_mcap.t == rec.t).all() and (from_mcap.phase == rec.phase).all()
        assert np.array_equal(from_mcap.vec("dock"), rec.vec("dock"), equal_nan=True)
        assert from_mcap.info["anchor_ned_m"] == json.loads((d / "mission.json").read_text())["anchor_ned_m"]
        with open(d / "carrier.mcap", "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            modes = [m.message for *_, m in reader.iter_decoded_messages(topics=["/pair0/carrier/log"])]
            statuses = [json.loads(msg.data) for _, _, msg in reader.iter_messages(topics=["/pair0/carrier/status"])]
            carrier_clock = {m.name: m.metadata for m in reader.iter_metadata()}["clock"]
            carrier_stats = reader.get_summary().statistics
        # one epoch for both files of the pair (lockstep: one simulated clock), so they line up in Foxglove
        assert int(carrier_clock["epoch_ns"]) == epoch
        assert abs(carrier_stats.message_start_time - stats.message_start_time) < 5e9
        assert modes[0].startswith("mode waiting") and "mode approaching" in modes and modes[-1] == "mode separated"
        closest = min(s["target_distance_m"] for s in statuses if s["target_distance_m"] is not None)
        carrier = json.loads((d / "carrier.json").read_text())
        assert closest == pytest.approx(carrier["closest_target_distance_m"], abs=1e-6)


    def test_three_pairs_fly_at_once_on_one_network(self, three_pairs):
        for i in range(3):
            d = three_pairs.root / "logs" / f"pair{i}"
            s = json.loads((d / "summary.json").read_text())
            assert s["p1"] and s["p2"] and s["p3"] and s["phase"] == "DONE", (i, s)
            info = json.loads((d / "mission.json").read_text())
            assert info["pair"] == f"pair{i}"
            assert info["anchor_ned_m"] is not None
        assert three_pairs.code == 0, three_pairs.text
        # Crosstalk on the bus itself is tested in test_bridge_pairs.py (distinct states per pair);
        # here three full stacks share one Zenoh router and every one of them completes.

    def test_demo_live_serves_each_pair_under_its_prefix_while_it_flies(self, three_pairs):
        """``marsupial demo --live`` serves each pair's flight to a Foxglove WebSocket client while it
        flies (the protocol the Foxglove app speaks, on test-chosen loopback ports)."""
        f = three_pairs
        assert f.not_seen_flying is None, (f.not_seen_flying, f.text[-3000:])
        # the flights end (whether P1-P3 held is test_three_pairs_fly_at_once_on_one_network's business:
        # here, what the viewer saw)
        assert f.code in (0, 1), f.text
        for i, v in enumerate(f.viewers):
            assert v.subprotocol in ("foxglove.sdk.v1", "foxglove.websocket.v1")
            topics = {c["topic"] for c in v.channels.values()}
            assert topics and all(t.startswith(f"/pair{i}/") for t in topics), topics
            assert {c["schemaName"] for c in v.channels.values()} >= {"foxglove.FrameTransform", "foxglove.SceneUpdate",
                                                                     "foxglove.Log", "marsupial.Phase"}
            phases = [v.decode(f"/pair{i}/phase", p)["phase"] for _, p, _ in v.messages(f"/pair{i}/phase")]
            assert phases[-1] == "DONE" and "NAVIGATING" in phases, phases[-5:]
            poses = [v.decode(f"/pair{i}/tf/passenger", p) for _, p, _ in v.messages(f"/pair{i}/tf/passenger")]
            assert poses[-1].child_frame_id == f"pair{i}/passenger/base_link_frd"
            assert poses[-1].parent_frame_id == "map_ned"
            assert poses[-1].translation.x - poses[0].translation.x > 10.0  # it flew towards the target (24 m N)
            times = [t for t, _, _ in v.messages(f"/pair{i}/phase")]
            # epoch time [ns]: the demo's epoch plus the simulated clock (a lockstep flight of < 60 s)
            assert times == sorted(times) and times[0] > 1.5e18 and times[-1] - times[0] < 60e9
        assert f"live view of pair1: ws://127.0.0.1:{f.port + 1}" in f.text


def _ros2_config(tmp_path, cmd_vel_type: str, attachment: str, mode: str) -> Path:
    """demo.toml with ``carrier.ros2.cmd_vel_type``, ``rmw_attachment`` and ``zenoh.mode`` set."""
    config = tmp_path / "demo.toml"
    text = DEMO.read_text().replace('[zenoh]\nmode = "peer"\n', f'[zenoh]\nmode = "{mode}"\n', 1)
    assert f'mode = "{mode}"' in text
    config.write_text(text + f'\n[carrier.ros2]\ncmd_vel_type = "{cmd_vel_type}"\nrmw_attachment = "{attachment}"\n')
    return config


def _assert_ros2_robot(tmp_path, cmd_vel_type: str, attachment: str) -> None:
    ros2 = json.loads((tmp_path / "logs" / "pair0" / "carrier.json").read_text())["ros2"]
    assert ros2["cmd_vel_type"] == f"geometry_msgs/msg/{cmd_vel_type}" and ros2["robot_attachment"] == attachment
    assert ros2["robot_token_seen"] and ros2["dropped"] == {}, ros2


class TestARealCarrierInterface:
    @pytest.mark.parametrize("carrier", ["mavlink", "ros2"])
    def test_demo_with_a_real_carrier_interface_holds_p1_p3_and_the_guard(self, tmp_path, carrier):
        """--carrier mavlink: the carrier controller flies a mock PX4 Ackermann rover (sysid 2) in
        OFFBOARD; --carrier ros2: it drives a ROS-2-shaped diff-drive robot on rmw_zenoh keys
        (TwistStamped, rmw_zenoh's current attachment, peer mode; the other command type, the legacy
        attachment and client mode: TestARos2Robot). Each robot steps on the carrier's lockstep clock."""
        config = ("--config", str(_ros2_config(tmp_path, "TwistStamped", "current", "peer"))) if carrier == "ros2" else ()
        out = _demo(tmp_path, "--carrier", carrier, *config, "--plot", "")  # no figure: TestTheDemoFlight checks the one-pair plot
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
        if carrier == "ros2":
            _assert_ros2_robot(tmp_path, "TwistStamped", "current")


class TestARos2Robot:
    def test_demo_drives_a_ros2_robot_of_the_other_command_type(self, tmp_path):
        """``carrier.ros2.cmd_vel_type`` and ``rmw_attachment`` in the config: the ROS-2-shaped robot
        takes only that type (its subscription's key carries the type and its hash) and speaks that
        attachment, and the flight holds P1-P3 (TwistStamped with the current attachment, in peer
        mode: TestARealCarrierInterface). ``zenoh.mode = "client"``: rmw_zenoh's topology, every
        process a client of the demo's router (which plays ``rmw_zenohd``), the robot included."""
        config = _ros2_config(tmp_path, "Twist", "legacy", "client")
        out = _demo(tmp_path, "--carrier", "ros2", "--config", str(config), "--plot", "")
        s = json.loads((tmp_path / "logs" / "pair0" / "summary.json").read_text())
        assert s["p1"] and s["p2"] and s["p3"] and s["phase"] == "DONE", s
        assert out.returncode == 0, out.stdout + out.stderr
        _assert_ros2_robot(tmp_path, "Twist", "legacy")
