"""One step in one place: for the same config, ``marsupial simulate --json`` (the mission flown
in-process, sim/batch/recovery.py) and ``marsupial demo`` (three processes over real UDP and
Zenoh, in lockstep) fly the same flight, leg by leg: docked or not, the approaches flown, the
contact's error within 0.02 m, the separation within 0.1 s (tests/support/agreement.py). Here:
configs/cycle.toml's hover copy (two targets), and it and configs/recovery.toml with
configs/px4_sitl.toml's tracking terms; configs/recovery.toml itself is checked on the flight of
test_recovery_demo.py."""
from __future__ import annotations

import json
import subprocess
import sys
import tomllib

import pytest

from mission.config.schema import load_config
from tests.conftest import CONFIGS
from tests.support.agreement import TRACKING_KEYS, assert_same_flight, hover_cycle, simulated, with_px4_tracking

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]  # a demo flight and a simulated one per config

CASES = {
    "cycle-hover": hover_cycle,
    "cycle-hover-px4-tracking": lambda: with_px4_tracking(hover_cycle()),
    "recovery-px4-tracking": lambda: with_px4_tracking((CONFIGS / "recovery.toml").read_text()),
}


@pytest.fixture(scope="module", params=sorted(CASES))
def both(request, tmp_path_factory):
    """(the demo's summary.json, simulate --json's summary) of one case's config."""
    root = tmp_path_factory.mktemp(request.param)
    path = root / f"{request.param}.toml"
    path.write_text(CASES[request.param]())
    cmd = [sys.executable, "-m", "mission.cli", "demo", "--config", str(path), "--log-root", str(root / "logs"),
           "--plot", "", "--timeout", "200"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    return json.loads((root / "logs" / "pair0" / "summary.json").read_text()), simulated(path)


def test_simulate_flies_the_demos_flight_leg_by_leg(both):
    demo, sim = both
    assert_same_flight(demo, sim)
    assert all(leg["contact"] is not None for leg in sim.get("legs") or [sim])  # every leg docked


def test_the_px4_tracking_terms_are_px4_sitls():
    """The cases' tracking terms are px4_sitl.toml's, whatever the base config says."""
    px4 = load_config(CONFIGS / "px4_sitl.toml").mission
    text = with_px4_tracking((CONFIGS / "recovery.toml").read_text())
    mission = tomllib.loads(text)["mission"]
    assert {k: mission[k] for k in TRACKING_KEYS} == {k: getattr(px4, k) for k in TRACKING_KEYS}
