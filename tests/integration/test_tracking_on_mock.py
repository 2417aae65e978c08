"""``configs/px4_sitl.toml`` on the mock vehicle with PX4 SITL's estimate errors
(``estimate_error`` 1, :mod:`sim.vehicle.estimator`) predicts real PX4: its riding offset, last
metre and hover speed within 30 % of PX4's (``tests/data/px4_hold_figures.json``, five real PX4
SITL flights of the same file; docs/px4-hold.md), and it holds the dock and the target as PX4
does. Lockstep: the same flights whatever the machine's load."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sim.vehicle.faults import FaultOptions
from tests.support.mission_harness import flying_pair

PX4_FIGURES = Path(__file__).resolve().parents[1] / "data" / "px4_hold_figures.json"
FIGURES = ("max_offset_before_separation_m", "last_metre_s", "hover_speed_m_s")
# eight draws of the estimate's errors; their mean is the mock's prediction. One draw's hover speed
# spreads 0.11-0.25 m/s: the mean of seeds 1-4 was 0.136 m/s (0.64x PX4) once the errors' clock
# started at take-off, of seeds 1-8 0.164 m/s (0.77x); riding offset 0.170 m, last metre 1.60 s.
# With the velocity error's correlation time as PX4's truth measured it (1.5 s, was 2 s): seeds 1-8
# 0.177 m, 1.61 s, 0.167 m/s (0.88x, 0.97x, 0.79x PX4)
SEEDS = (1, 2, 3, 4, 5, 6, 7, 8)
pytestmark = pytest.mark.timeout(300)  # eight lockstep flights, ~12 s of CPU each


def test_the_mock_predicts_px4_holding_the_dock_and_the_target(tmp_path):
    px4 = json.loads(PX4_FIGURES.read_text())["mean"]
    flights = []
    for seed in SEEDS:
        with flying_pair(tmp_path / f"s{seed}", config="px4_sitl.toml",
                         vehicle={"estimate_error": 1.0, "faults": FaultOptions(seed=seed)}) as pair:
            out = pair.finish()
        assert out.phase == "DONE", (out.reason, out.detail)
        s = json.loads((pair.log_dir / "summary.json").read_text())
        assert s["p1"] and s["p2"] and s["p3"], s
        assert s["max_target_distance_after_arrival_m"] <= 0.5  # once within the arrival radius, never outside
        assert s["relative_input_jump_m_s"] <= 0.05
        assert s["position_rate_hz"] >= 40.0  # the mock honours SET_MESSAGE_INTERVAL (50 Hz asked)
        flights.append(s)
    for name in FIGURES:
        mock = float(np.mean([s[name] for s in flights]))
        assert mock == pytest.approx(px4[name], rel=0.3), f"{name}: mock {mock:.3f}, PX4 {px4[name]:.3f}"
