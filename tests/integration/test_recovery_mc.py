"""The recovery's Monte-Carlo is true to the mock: one recovery flown both as a lockstep
``marsupial demo --config configs/recovery.toml`` (three processes over UDP and Zenoh) and in the
in-process simulation (sim/batch/recovery.py) gives the same contact figures. The demo draws the
recovery's figure beside its flight plot, and `marsupial plot` draws it from the flight's MCAP too."""
from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from mission.config.schema import load_config
from mission.phases import Phase
from mission.record import read_record
from sim.batch.recovery import Scenario, fly
from tests.conftest import CONFIGS

pytestmark = [pytest.mark.slow, pytest.mark.timeout(240)]  # a demo flight and a simulated one, on a shared machine

CONFIG = CONFIGS / "recovery.toml"
# How close the two flights' contacts are (docs/recovery.md): the simulation samples the carrier
# and the vehicle as the lockstep demo does, so they differ only by the wire's float32 rounding
# and the moment the vehicle's first HEARTBEAT and the carrier's first sample arrive.
TOLERANCE = {"horizontal_error_m": 0.01, "height_error_m": 0.01, "horizontal_relative_speed_m_s": 0.02,
             "vertical_relative_speed_m_s": 0.02}
TIME_TOLERANCE_S = 0.1  # contact time, counted from the start of riding [s]


def steady_course(rec) -> tuple[float, float]:
    """The carrier's recovery course in a flight record: (speed [m/s], heading [deg] NED) at the
    first approach (steady by then)."""
    i = int(np.flatnonzero(rec.phase == Phase.APPROACH)[0])
    v = rec.vec("v_c")[i]
    return float(math.hypot(v[0], v[1])), math.degrees(math.atan2(v[1], v[0])) % 360.0


def test_the_simulation_docks_as_the_lockstep_demo_does(tmp_path):
    out = subprocess.run([sys.executable, "-m", "mission.cli", "demo", "--config", str(CONFIG), "--log-root",
                          str(tmp_path / "logs"), "--plot", str(tmp_path / "flight.png"), "--timeout", "200"],
                         capture_output=True, text=True, timeout=220)
    assert out.returncode == 0, out.stdout + out.stderr
    demo_dir = tmp_path / "logs" / "pair0"
    rec = read_record(demo_dir)
    demo = rec.info["recovered"]["contact"]
    assert demo is not None and (tmp_path / "flight-recovery.png").stat().st_size > 10_000
    speed, heading = steady_course(rec)
    sim = fly(load_config(CONFIG), Scenario(speed_m_s=speed, heading_deg=heading))
    ours = sim.summary["contact"]
    assert sim.docked and ours["attempts"] == demo["attempts"]
    for key, tolerance in TOLERANCE.items():
        assert ours[key] == pytest.approx(demo[key], abs=tolerance), (key, ours, demo)
    riding_demo = rec.t[int(np.argmax(rec.phase == Phase.RIDING))]
    riding_sim = sim.record.t[int(np.argmax(sim.record.phase == Phase.RIDING))]
    assert ours["time_s"] - riding_sim == pytest.approx(demo["time_s"] - riding_demo, abs=TIME_TOLERANCE_S)
    assert sim.summary["deck_violations"] == 0
    # the recovery's figure is drawn from the flight's MCAP as from its CSV
    plotted = subprocess.run([sys.executable, "-m", "mission.cli", "plot", str(demo_dir / "flight.mcap"), "--out",
                              str(tmp_path / "from-mcap.png")], capture_output=True, text=True, timeout=120)
    assert plotted.returncode == 0, plotted.stdout + plotted.stderr
    assert (tmp_path / "from-mcap-recovery.png").stat().st_size > 10_000
