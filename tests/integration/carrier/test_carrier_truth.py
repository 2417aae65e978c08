"""``marsupial carrier configs/relnav.toml`` as a process (real Zenoh on loopback): with
``world.carrier_gnss.enabled`` it publishes its robot's state as an erring GNSS gives it (metres
off, the seeded bias) on its state key, and the robot's truth on the sim-only key
``marsupial/<pair>/sim/carrier_truth`` (sim/robots/truth.py); with the errors off it publishes no
truth. The carrier stands (no passenger rides), so its truth is its start."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from mission.config.schema import load_config
from sim.gnss import CarrierGnss
from sim.net import stop_process
from sim.robots.truth import truth_key
from tests.conftest import CONFIGS, ROOT, free_port
from tests.support.zenoh_util import endpoint, peer, wait_for

pytestmark = pytest.mark.timeout(90)

RELNAV = CONFIGS / "relnav.toml"


def _fly(config: Path, pair: str, seconds: float = 30.0) -> tuple[list[dict], list[dict]]:
    """The states and truths the carrier of ``config`` published on pair ``pair`` (JSON dicts)."""
    ep = endpoint(free_port())
    session = peer(listen=[ep])
    got: dict[str, list[dict]] = {"state": [], "truth": []}
    lock = threading.Lock()

    def keep(name: str):
        def on(sample) -> None:
            with lock:
                got[name].append(json.loads(sample.payload.to_bytes()))
        return on

    subs = [session.declare_subscriber(f"marsupial/{pair}/carrier/state", keep("state")),
            session.declare_subscriber(truth_key(pair), keep("truth"))]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "mission.cli", "carrier", str(config), "--pair", pair,
                             "--zenoh-connect", ep, "--speed", "1"], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        wait_for(lambda: len(got["state"]) >= 30, seconds, "30 carrier states")
    finally:
        stop_process(proc)
        for sub in subs:
            sub.undeclare()
        session.close()
    with lock:
        return list(got["state"]), list(got["truth"])


def test_the_carrier_publishes_its_erring_state_and_its_truth_apart():
    cfg = load_config(RELNAV)
    states, truths = _fly(RELNAV, "truth0")
    assert truths, "no truth on the sim-only key"
    start = np.asarray(cfg.scenario.carrier_start, float)
    assert all(np.allclose(t["position"], start) for t in truths)  # standing: its truth is its start
    off = np.array([np.asarray(s["position"], float) - start for s in states])
    # the published state is the truth plus the seeded bias (1.4 m per horizontal axis here) and
    # 0.3 m of noise: measured (2.76, -3.54) m horizontally over 30 states, the bias CarrierGnss
    # of world.carrier_gnss draws (the in-process simulation's) being (2.86, -3.58) m
    bias = CarrierGnss(cfg.world.carrier_gnss).bias.value_ned_m
    assert np.hypot(*off[:, :2].mean(axis=0)) > 1.0
    assert np.linalg.norm(off[:, :2].mean(axis=0) - bias[:2]) < 1.0, (off[:, :2].mean(axis=0), bias)


def test_without_the_errors_the_carrier_publishes_no_truth(tmp_path):
    plain = tmp_path / "plain.toml"
    plain.write_text(RELNAV.read_text().replace("enabled = true\nbias_sigma_m = 1.4", "enabled = false\nbias_sigma_m = 1.4", 1))
    assert not load_config(plain).world.carrier_gnss.enabled
    states, truths = _fly(plain, "truth1")
    assert truths == [] and all(np.allclose(s["position"], [0.0, 0.0, 0.0]) for s in states)
