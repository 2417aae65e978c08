"""The demo's live display and the plot command on a folder of flight logs (no sockets)."""
from __future__ import annotations

import io
import json

import numpy as np
from click.testing import CliRunner

from mission.record.recorder import FlightRecorder
from mission.cli.run import plot
from mission.report import event_line
from sim.progress import PHASE_STEPS, PairProgress, phase_step


def test_phase_steps_count_hold_and_land_as_one_step():
    assert phase_step("PREFLIGHT") == 1 and phase_step("HOLD") == phase_step("LAND") == len(PHASE_STEPS) - 1
    assert phase_step("DONE") == len(PHASE_STEPS) and phase_step("ABORT") is None


def test_each_pair_has_its_own_bar_that_never_runs_backwards():
    out = io.StringIO()
    display = PairProgress(["pair0", "pair1", "pair2"], tty=True, out=out)
    display.update("pair0", "RIDING", "[mission 5 s] phase RIDING")
    display.update("pair1", "PREFLIGHT", "[mission 0 s] phase PREFLIGHT")
    display.update("pair2", "STREAMING", "[mission 1 s] phase STREAMING")
    assert [display.bars[p].n for p in ("pair0", "pair1", "pair2")] == [6, 1, 2]
    display.update("pair0", "ABORT", "[mission 6 s] phase ABORT (carrier_lost: x)")
    assert display.bars["pair0"].n == 6
    for ph in ("HOLD", "DONE"):
        display.update("pair1", ph, f"phase {ph}")
    assert display.bars["pair1"].n == display.bars["pair1"].total == len(PHASE_STEPS)
    display.close()


def test_without_a_terminal_the_display_is_plain_phase_lines():
    out = io.StringIO()
    display = PairProgress(["pair0", "pair1"], tty=False, out=out)
    display.update("pair0", "RIDING", "[mission 4.00 s] phase RIDING")
    display.update("pair1", "JOIN", "[mission 3.00 s] phase JOIN")
    display.close()
    assert out.getvalue() == "pair0: [mission 4.00 s] phase RIDING\npair1: [mission 3.00 s] phase JOIN\n"
    assert "\r" not in out.getvalue()


def test_phase_lines_label_both_clocks():
    assert event_line("phase JOIN", 3.0, None).startswith("[mission    3.00 s]")
    assert event_line("phase SEPARATED", 17.06, 4.65) == "[mission   17.06 s | t   12.41 s] phase SEPARATED"


def _fake_flight(directory, offset):
    rec = FlightRecorder(directory, {"target_ned_m": [20.0, 0.0, -5.0], "obstacles": [], "bc_m": 8.0,
                                     "dock_offset_ned_m": [0, 0, -1.5], "dock_tolerance_m": 0.5, "arrival_radius_m": 0.5})
    for k in range(40):
        phase = "JOIN" if k < 5 else ("RIDING" if k < 25 else "NAVIGATING")
        x_c = np.array([k * 0.5 + offset, 0.0, 0.0])
        dock = x_c + [0, 0, -1.5]
        x_p = dock if k < 25 else dock + [(k - 25) * 0.5, 0, -0.2 * (k - 25)]
        z = np.zeros(3)
        rec.record(k * 0.1, phase, x_p, z, x_c, z, dock, x_p, 0.0, z, z, z, False, 0.0, "OFFBOARD", True)
    rec.close({"phase": "DONE"}, {"separation_time_s": 2.5})


def test_plot_of_a_folder_of_pairs_plots_each_pair(tmp_path):
    for i, name in enumerate(("pair0", "pair1")):
        _fake_flight(tmp_path / name, i)
    (tmp_path / "flight.png").write_bytes(b"")  # the demo's own plot beside the pair folders
    result = CliRunner().invoke(plot, [str(tmp_path)], standalone_mode=False)
    assert result.exception is None, result.output
    for name in ("pair0", "pair1"):
        assert (tmp_path / name / "flight.png").stat().st_size > 20_000
        assert f"plot written to {tmp_path / name / 'flight.png'}" in result.output
    summary = json.loads((tmp_path / "pair0" / "summary.json").read_text())
    assert summary["separation_time_s"] == 2.0  # 2.5 on the mission clock, riding from 0.5


def test_a_riding_tick_without_a_dock_measures_no_offset_and_leaves_p1_decidable(tmp_path):
    """A tick on which the vehicle's telemetry went silent decides no dock (NaN in the record):
    the riding offset is the largest over the ticks that had one, not NaN (which made P1 false
    and the offset None on a real-PX4 flight)."""
    rec = FlightRecorder(tmp_path, {"target_ned_m": [20.0, 0.0, -5.0], "obstacles": [], "bc_m": 8.0,
                                    "dock_offset_ned_m": [0, 0, -1.5], "dock_tolerance_m": 0.5, "arrival_radius_m": 0.5})
    z, nan = np.zeros(3), np.full(3, np.nan)
    for k in range(30):
        phase = "RIDING" if k < 20 else "NAVIGATING"
        x_c = np.array([k * 0.5, 0.0, 0.0])
        dock = nan if k == 7 else x_c + [0, 0, -1.5]
        x_p = x_c + [0.3 if k == 12 else 0.0, 0, -1.5]  # 0.3 m off the dock once
        rec.record(k * 0.1, phase, x_p, z, x_c, z, dock, x_p, 0.0, z, z, z, False, 0.0, "OFFBOARD", True)
    s = rec.close()
    assert s["max_offset_before_separation_m"] == 0.3
