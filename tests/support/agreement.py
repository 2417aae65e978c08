"""The same config flown two ways, the lockstep demo (three processes) and ``marsupial simulate
--json`` (in-process, sim/batch/recovery.py): what must agree leg by leg, and the configs it is
measured on (docs/recovery.md, "The simulation flies the demo's flight")."""
from __future__ import annotations

import contextlib
import io
import json
import re
import subprocess
from pathlib import Path
from typing import Any

from mission.cli import main
from mission.config.schema import load_config
from sim.net import stop_process
from tests.conftest import CONFIGS

# What the two may differ by (docs/recovery.md): the wire's float32 rounding and the moment the
# vehicle's first HEARTBEAT and the carrier's first sample arrive shift the controller's ticks
# against the carrier's 30 Hz steps by up to one carrier step.
CONTACT_TOLERANCE_M = 0.02  # horizontal and height error at contact [m]
SEPARATION_TOLERANCE_S = 0.1  # separation time from the leg's start of riding [s]

#: The tracking terms of a [mission] section (mission/core/tracking.py): the loop that holds the dock.
TRACKING_KEYS = ("setpoint", "track_gain", "position_lead", "drag_ff_per_s", "integral_gain", "integral_window_m",
                 "velocity_bias_tau_s", "bias_compensation_s", "accel_lead_s", "damping_per_s",
                 "reference_slow_lag_m", "reference_stop_lag_m")


def hover_cycle() -> str:
    """configs/cycle.toml riding hovering 1.5 m above the deck (the simulation has no deck)."""
    return ((CONFIGS / "cycle.toml").read_text().replace('ride = "deck"\n', 'ride = "hover"\n')
            .replace("dock_offset_ned_m = [0.0, 0.0, -0.5]", "dock_offset_ned_m = [0.0, 0.0, -1.5]")
            .replace("z_max_m = -0.3", "z_max_m = -0.5"))


def with_px4_tracking(text: str) -> str:
    """A config's text with configs/px4_sitl.toml's tracking terms in its [mission] section."""
    px4 = load_config(CONFIGS / "px4_sitl.toml").mission
    for key in TRACKING_KEYS:
        text = re.sub(rf"^{key} = .*\n", "", text, flags=re.MULTILINE)
    terms = "".join(f"{key} = {json.dumps(getattr(px4, key))}\n" for key in TRACKING_KEYS)
    return text.replace("[mission]\n", "[mission]\n" + terms, 1)


def simulated(path: str | Path) -> dict[str, Any]:
    """``marsupial simulate PATH --json``, called in-process: (exit code, summary)."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["simulate", str(path), "--json", "--no-progress"])
    assert code == 0, out.getvalue()[-2000:]
    return json.loads(out.getvalue())


def demo_while_simulated(cmd: list[str], path: str | Path,
                         timeout_s: float) -> tuple[subprocess.CompletedProcess[str], dict[str, Any] | AssertionError]:
    """Run the demo command ``cmd`` and, while it flies, :func:`simulated` of ``path`` in this
    process (the demo in lockstep, the simulation in-process: neither changes the other's flight);
    (the finished demo, the simulation's summary or its failure, for the test that checks it to
    raise: the demo's own tests go on). ``timeout_s``: the demo's, wall clock."""
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as demo:
        try:
            sim: dict[str, Any] | AssertionError
            try:
                sim = simulated(path)
            except AssertionError as exc:
                sim = exc
            stdout, stderr = demo.communicate(timeout=timeout_s)
        finally:
            stop_process(demo)  # (a no-op unless the demo overran or the test was interrupted)
    return subprocess.CompletedProcess(cmd, demo.returncode, stdout, stderr), sim


def simulation(sim: dict[str, Any] | AssertionError) -> dict[str, Any]:
    """The simulation's summary from :func:`demo_while_simulated`; its failure raised here."""
    if isinstance(sim, AssertionError):
        raise sim
    return sim


def legs(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """A summary's legs (a one-target flight: itself, its one leg)."""
    return summary.get("legs") or [summary]


def assert_same_flight(demo: dict[str, Any], sim: dict[str, Any]) -> None:
    """Every leg: docked or not, the approaches flown, the contact's horizontal and height error
    within :data:`CONTACT_TOLERANCE_M`, the separation time within :data:`SEPARATION_TOLERANCE_S`."""
    assert sim["simulated"] == "mission"
    assert len(legs(demo)) == len(legs(sim)), (demo, sim)
    for k, (d, s) in enumerate(zip(legs(demo), legs(sim))):
        dc, sc = d.get("contact"), s.get("contact")
        assert (dc is None) == (sc is None), (k, dc, sc)
        assert d["separation_time_s"] is not None and s["separation_time_s"] is not None, (k, d, s)
        assert abs(d["separation_time_s"] - s["separation_time_s"]) <= SEPARATION_TOLERANCE_S, \
            (k, d["separation_time_s"], s["separation_time_s"])
        if dc is not None:
            assert dc["attempts"] == sc["attempts"], (k, dc, sc)
            for key in ("horizontal_error_m", "height_error_m"):
                assert abs(dc[key] - sc[key]) <= CONTACT_TOLERANCE_M, (k, key, dc, sc)
