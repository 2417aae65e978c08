"""The live view: ``marsupial demo --live`` serves each pair's flight to a Foxglove WebSocket
client while it flies (the protocol the Foxglove app speaks, on test-chosen loopback ports)."""
from __future__ import annotations

import subprocess
import sys
import time

import pytest

from sim.net import stop_process, wait_for
from sim.testing.foxglove_viewer import LiveViewer
from tests.conftest import free_port

pytestmark = pytest.mark.slow


def two_free_ports() -> int:
    """A free TCP port p on 127.0.0.1 whose neighbour p + 1 is free too (pair i serves on p + i)."""
    for _ in range(100):
        a, b = free_port(), free_port()
        if b == a + 1:
            return a
    raise AssertionError("no two neighbouring free ports")


def test_demo_live_serves_each_pair_under_its_prefix_while_it_flies(tmp_path):
    port = two_free_ports()
    cmd = [sys.executable, "-m", "mission.cli", "demo", "--pairs", "2", "--live", f"127.0.0.1:{port}",
           "--log-root", str(tmp_path / "logs"), "--plot", "", "--timeout", "120"]
    out = open(tmp_path / "demo.out", "w")
    demo = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, text=True)
    try:
        viewers = [LiveViewer(f"ws://127.0.0.1:{port + i}", topics={f"/pair{i}/phase", f"/pair{i}/tf/passenger"},
                              connect_timeout_s=60.0) for i in range(2)]
        with viewers[0] as v0, viewers[1] as v1:
            # the pose and the phase arrive while the pair flies (before the demo has ended)
            wait_for(lambda: _flying_seen(v0, "pair0") and _flying_seen(v1, "pair1") and demo.poll() is None,
                     90.0, "poses and a flying phase from both pairs while they fly")
            # the flights end (whether P1-P3 held is test_demo's business: here, what the viewer saw)
            assert demo.wait(timeout=120) in (0, 1), (tmp_path / "demo.out").read_text()
        for i, v in enumerate((v0, v1)):
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
        text = (tmp_path / "demo.out").read_text()
        assert f"live view of pair1: ws://127.0.0.1:{port + 1}" in text
    finally:
        stop_process(demo, 30.0)
        out.close()


def _flying_seen(v: LiveViewer, pair: str) -> bool:
    time.sleep(0.05)  # (polled: leave the viewers' threads the time to receive)
    phases = v.messages(f"/{pair}/phase")[-3:]
    return bool(v.messages(f"/{pair}/tf/passenger")) and any(
        v.decode(f"/{pair}/phase", p)["phase"] in ("JOIN", "RIDING", "SEPARATED", "NAVIGATING") for _, p, _ in phases)
