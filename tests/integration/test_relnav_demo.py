"""``marsupial demo --config configs/relnav.toml`` end to end (three processes over real UDP and
Zenoh on loopback, in lockstep): dock with no shared frame. The carrier flies the world's GNSS
errors (``marsupial carrier`` wraps its robot in them, ~2 m of bias) and publishes its truth only
on the sim-only key; the mock vehicle carries its own ~1 m bias, follows the carrier's truth with
its deck, and renders the downward camera's frames from the true poses; the mission's marker feed
runs the detector on those pixels. The figures are held against the world's truth (the mock's
true position, the carrier's truth: ``truth.json``, ``sim.robots.truth.demo_truth``), each bound
a measured number (docs/relnav.md, "The lockstep demo"); a target of the issue that is missed is
asserted at its measured value, with the reason.

Before the turn check measured a slope over a window (eleven flights: seed 0 five times, seeds 1-3
twice each), nine fell back on leg 1 after three go-arounds, every one "the carrier turns at
20.2-25.3 deg/s (limit 20)" while the true carrier drove straight: the estimator's velocity
swinging near the deck, read by a difference of two samples 0.25 s apart (docs/relnav.md). With
the slope over recovery.carrier_rate_window_s = 1 s (seven flights: seed 0 four times, seeds 1-3
once), every flight docked both legs, 12 of 14 legs at the first approach (seed 0: both, every
time), the other two at the second after "off the deck on the descent", and no go-around on the
turn check. Seed 0 is still not deterministic: its four flights gave two sets of figures, each
twice (true contact 0.017 / 0.042 m and 0.098 / 0.026 m).

With the marker on the deck under the hover point (2026-12-04: vision.marker_offset_ned_m, the P3
guard's margin 3 m, relnav.accel_noise_m_s2 0.3, the estimate restarted after a run of rejected
markers, the deck's velocity slewed at the carrier's acceleration limit) the camera sees the deck
while riding: six flights (seeds 0-2) docked both legs at the first approach, true contact
0.016-0.118 m."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from mission.config.schema import load_config
from mission.flightdata.read import log_lines, read_messages
from tests.conftest import CONFIGS

pytestmark = [pytest.mark.slow,
              # Rendering the camera in the mock and detecting the marker in the mission cost ~10 ms a frame
              # each at 30 Hz: a flight took 1.5-7 min of wall time on a machine at load 7-30 (105 s at load 1),
              # 55-105 s of the demo's processes' CPU, beyond the suite's 120 s a test.
              pytest.mark.timeout(900)]

RELNAV = CONFIGS / "relnav.toml"


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    root = tmp_path_factory.mktemp("relnav")
    cmd = [sys.executable, "-m", "mission.cli", "demo", "--config", str(RELNAV), "--log-root", str(root / "logs"),
           "--plot", "", "--timeout", "780"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=840)
    log = root / "logs" / "pair0"
    s = json.loads((log / "summary.json").read_text())
    truth = json.loads((log / "truth.json").read_text())["truth_legs"]
    events = [text for _, _, text in log_lines(read_messages(log / "flight.mcap", {"/pair0/log"}), "/pair0/log")]
    return log, out, s, truth, events


LATE_WORLD = Path(__file__).resolve().parents[1] / "support" / "late_world"  # its sitecustomize.py
SHORT_S = 10.0  # the perturbed flight's mission.max_duration_s [s]: the records parted at t = 3.62 s


@pytest.fixture(scope="module")
def late_world_flight(tmp_path_factory):
    """The first 10 s of the same flight (~15 s of CPU) with its wall timing perturbed
    (tests/support/late_world: the mock hears the carrier's first truth samples 150 ms late each,
    every camera exposure takes 3 ms longer); its record.csv."""
    root = tmp_path_factory.mktemp("relnav_late")
    short = root / "relnav_short.toml"
    text = RELNAV.read_text()
    assert "\nmax_duration_s = 300.0" in text
    short.write_text(text.replace("\nmax_duration_s = 300.0", f"\nmax_duration_s = {SHORT_S}"))
    env = {**os.environ, "MARSUPIAL_LATE_WORLD": "1",
           "PYTHONPATH": os.pathsep.join(p for p in (str(LATE_WORLD), os.environ.get("PYTHONPATH")) if p)}
    cmd = [sys.executable, "-m", "mission.cli", "demo", "--config", str(short), "--log-root", str(root / "logs"),
           "--plot", "", "--timeout", "600"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=660, env=env)
    log = root / "logs" / "pair0"
    assert (log / "record.csv").exists(), out.stderr[-3000:]
    touchdowns = json.loads((log / "vehicle.json").read_text())["deck"]["touchdowns"]
    return (log / "record.csv").read_bytes(), touchdowns


def test_the_record_does_not_depend_on_wall_timing(flight, late_world_flight):
    """Lockstep: the flight's record is a function of simulated time only. Before, the mock's deck was
    first known when the carrier feed's gate had bound its truth as it *arrived* (0.075 s in one run,
    0.74 s with this perturbation) and the camera's capture grid took its phase from that first
    frame, so the two records parted at t = 3.62 s (the fused marker); now the deck is known at the
    vehicle's first pass (its first physics step, 0.005 s) and the frames are captured on the grid
    k / vision.rate_hz (docs/relnav.md, "The lockstep demo"). The perturbed 10 s flight's rows up
    to 9.5 s are the full flight's byte for byte."""
    log, _, _, _, _ = flight
    late, touchdowns = late_world_flight
    full = json.loads((log / "vehicle.json").read_text())["deck"]["touchdowns"]
    assert touchdowns[0] == full[0] and full[0]["t_s"] == 0.005, (touchdowns[0], full[0])  # known at the first pass

    def rows(data: bytes) -> list[bytes]:
        return [line for line in data.splitlines()[1:] if float(line.split(b",", 1)[0]) < SHORT_S - 0.5]
    ours, theirs = rows(late), rows((log / "record.csv").read_bytes())
    assert len(ours) >= 450, len(ours)  # 50 Hz from t = 0.02 s
    first = next((i for i, (a, b) in enumerate(zip(ours, theirs)) if a != b), min(len(ours), len(theirs)))
    assert ours == theirs, (len(ours), len(theirs), ours[first:first + 1], theirs[first:first + 1])


def test_both_legs_dock_on_the_marker_within_the_true_contact_bound(flight):
    """Both legs docked: the true contact error within the issue's 0.10 m (seed 0: 0.086 / 0.042 m
    with the rangefinder; 0.008-0.109 m over earlier flights' legs), the true vertical within 0.15 m (-0.021 to -0.131 m,
    contact being declared 0.1 m over the dock point), at most two approaches (measured: seed 0
    one each leg, four times; seeds 1 and 2 two on one leg),
    and a go-around only ever "off the deck on the descent" (the vehicle, lined up at the gate,
    hunting 0.03-0.27 m and 0.03-0.39 m/s over the deck until out of line for gate_timeout_s),
    never the turn check (before: every go-around, nine flights of eleven fell back). Never a
    crash, never an abort."""
    log, out, s, truth, events = flight
    assert s["phase"] == "DONE", (s.get("reason"), s.get("detail"), out.stderr[-3000:])
    arounds = [e for e in events if e.startswith("go-around")]
    assert not any("the carrier turns at" in e for e in arounds), arounds  # the estimator's wobble is no turn
    # (every other go-around measured was "off the deck on the descent"; another reason is not a
    # failure of this flight as long as both legs dock within two approaches, below)
    assert len(s["legs"]) == len(truth) == 2, (s["legs"], truth)
    for leg, true in zip(s["legs"], truth):
        assert leg["outcome"] == "done" and leg["recovery_outcome"] == "docked", leg
        assert leg["contact"]["attempts"] <= 2, leg
        # the target, 0.10 m: seed 0 (deterministic: the deck and the camera step with the lockstep,
        # docs/lockstep.md) flies 0.086 / 0.042 m with the rangefinder and the carrier's acceleration
        # as the estimator's input (0.109 / 0.018 m before them)
        assert true["true_contact_horizontal_m"] <= 0.10, true
        assert abs(true["true_contact_vertical_m"]) <= 0.15, true  # contact is declared 0.1 m over the dock point
    deck = json.loads((log / "vehicle.json").read_text())["deck"]
    assert deck["crash"] is None, deck


def test_no_jump_at_a_switch_p1_p3_hold_and_the_true_ride_is_on_the_deck(flight):
    """P1-P3 and every phase switch within the issue's 0.05 m/s (0.04 measured), the command's own
    step at the separation too (P1's ``input_jump_m_s``). The relative input at the separation (the
    command less the carrier's velocity as recorded) also holds the recorded velocity's own step:
    the deck's state is handed on at its fix's time, moved back from the estimate's now with the
    acceleration the carrier sent (``v - a age``), so it steps by ``a`` times the change of age when a
    fix arrives, as a raw fix's does (0.1 m/s at 1 m/s^2 and 10 Hz); seed 0 0.041 / 0.056 m/s, the
    Monte-Carlo over 0.05 in 45 of 100 flights before that change and after it (docs/relnav.md,
    "The carrier's acceleration as the estimator's input"). The ride sees the
    marker on the deck under the hover point (vision.marker_offset_ned_m), and the carrier's
    acceleration fed forward is its law's over mission.carrier_accel_horizon_s (0.5 s), not over
    one carrier step, where the estimated velocity's noise made it a bang-bang +-1 m/s^2 that
    rocked the vehicle +-0.5 m about the dock (docs/relnav.md, "Riding on late fixes"). Seed 0:
    P1's figure (the estimate's riding offset held) 0.29 / 0.22 m against 0.5 (before: over 0.5
    on leg 1); true riding offset median 0.10 / 0.10 m (the issue's 0.3), max 0.31 / 0.21 m. With the altitude floor over the ground the estimate sees (the passenger's own
    estimate drifts 1 m vertically: a fixed floor lay at the hover point), seeds 0-2 hold P1 on
    every leg, 0.13-0.29 m, and exit 0 (bench/relnav_demo.py)."""
    log, out, s, truth, _ = flight
    cfg = load_config(RELNAV)
    assert s["p1"] and s["p2"] and s["p3"], s
    assert s["max_phase_switch_jump_m_s"] <= 0.05, s
    for leg, true in zip(s["legs"], truth):
        if "separation_time_s" in leg:
            assert leg["input_jump_m_s"] <= 0.05, leg
            assert leg["relative_input_jump_m_s"] <= 0.1, leg
            # seed 0: median 0.062 / 0.057 m, max 0.170 / 0.174 m (0.31 / 0.21 before the carrier's
            # acceleration was the estimator's input)
            assert true["true_riding_horizontal_median_m"] <= 0.1, true
            assert true["true_riding_horizontal_max_m"] <= 0.3, true  # the target
            assert leg["riding_offset_held_m"] <= cfg.mission.dock_tolerance_m, leg  # P1
    assert out.returncode == 0, out.stdout[-2000:]
    assert "truth: contact error, horizontal [m]" in out.stdout and "truth: riding offset" in out.stdout


def test_the_gate_lets_the_gnss_fixes_through_and_the_lockstep_loses_nothing(flight):
    """With relnav the carrier feed's gate allows a GNSS fix's noise (before, it dropped 78 of 385
    as 'velocity' or 'jump' and JOIN never settled): measured 0-4 dropped as 'velocity' of ~2000-4300;
    the lockstep lost no sample; the mock kept the truth's track (10 Hz)."""
    log, _, s, _, _ = flight
    feed = s["carrier_feed"]
    assert sum(feed["dropped"].get(k, 0) for k in ("velocity", "jump")) <= 20, feed
    assert s["lockstep"]["samples_lost"] == 0, s["lockstep"]
    track = json.loads((log / "vehicle.json").read_text())["track"]
    assert len(track["t_s"]) >= 500, len(track["t_s"])


def test_the_deck_is_streamed_as_landing_target_and_the_vehicle_accepts_every_one(flight):
    """``relnav.landing_target_rate_hz`` 10: the loop sends the deck's landing point while the
    estimate is converged (the marker in sight near the deck), and the mock vehicle, reading them
    by PX4's rule, accepts every one it got and refuses none."""
    log, _, s, _, _ = flight
    sent = s["link"]["tx_landing_targets"]
    counters = json.loads((log / "vehicle.json").read_text())["counters"]
    assert sent > 0, s["link"]
    assert counters["landing_targets_accepted"] == sent and counters["landing_targets_ignored"] == 0, counters
