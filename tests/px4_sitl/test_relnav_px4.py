"""Relative navigation on real PX4 SITL: the SIH quadrotor docks on the SIH rover with no shared
frame (``configs/px4_sitl_relnav.toml`` flown by :func:`bench.px4_relnav.fly`, one target): the
carrier publishes its state with a GNSS bias of about 2 m (``world.carrier_gnss``, seed 10), the
passenger's camera is rendered from SIH's truth of both vehicles by the camera node
(:mod:`sim.sitl.camera`) and the controller's marker feed detects the marker in the pixels. The
contact is judged against SIH's truth. Real time: 53 s of pytest's time here (2026-12-05), two
PX4s, flown alone (``conftest.px4_jobs``).

Skipped unless ``MARSUPIAL_PX4_SITL`` names a PX4 SITL build and the test may create network
namespaces (root, ``ip``). docs/relnav.md, "On real PX4 SITL".
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.conftest import CONFIGS
from tests.px4_sitl.conftest import px4_job

CONFIG = CONFIGS / "px4_sitl_relnav.toml"
pytestmark = [pytest.mark.slow, pytest.mark.timeout(360)]
SEED = 10  # the carrier's published GNSS error at the start: 2.2 m (bench.px4_relnav, docs/relnav.md)
ONE_TARGET = {"scenario.targets": "[[15.0, 0.0, -5.0]]"}


@px4_job("relnav", px4s=2)
def _fly_relnav(out: Path, build: Path) -> dict[str, Any]:
    from bench.px4_relnav import fly

    return {**fly(CONFIG, out / "f", SEED, overrides=ONE_TARGET), "directory": str(out / "f")}


@pytest.mark.px4_job("relnav")
def test_the_quadrotor_docks_on_the_rover_through_a_2_m_gnss_bias_by_the_camera(px4_jobs) -> None:
    """Docked within two approaches, 0.2 m from the rover's true dock point by SIH's truth, with
    the carrier's published position metres off its truth and the marker seen in the frames; the
    rover never truly within b c - 1 m (7 m) of the target."""
    row = px4_jobs["relnav"].result()
    (leg,) = row["legs"]
    assert row["published_error"]["first_10s_m"] > 1.0, row["published_error"]  # the bias is in what the carrier says
    assert row["camera"]["frames_sent"] > 100 and row["feeds"]["marker"]["detected"] > 100, (row["camera"], row["feeds"])
    assert leg["docked"] and leg["attempts"] <= 2, leg
    assert leg["true_error_m"] is not None and leg["true_error_m"] <= 0.2, leg
    # P3 against the truth, through the bias (seed 10's first target in the two-target flights: 7.47-8.41 m)
    assert leg["true_closest_m"] is not None and leg["true_closest_m"][0] >= 7.0, leg
    assert row["map_check_m"] is not None and row["map_check_m"] < 0.05  # the record and the truth on one clock


@pytest.mark.px4_job("relnav")
def test_the_flights_estimator_replays_from_its_log_and_holds_against_the_truth(px4_jobs) -> None:
    """The estimator's inputs in the flight's log replay it to the bit (``bench.relnav_replay``); by
    SIH's truth, on the approach, the marker is out of sight at most 10 % of the time, the relative
    position is within 0.1 m at the 95th percentile while it is in sight and within 0.2 m in all,
    and the error stays within 3 of the standard deviations the estimate states however long the
    marker is out of sight; it never re-initialised (a GNSS fix fused more than once, or
    over-trusted, reset it 2-5 times a flight: docs/relnav.md, "Replaying a flight's estimator").
    Measured on 26 flights with the 90 deg camera (ten-seed batches and this flight): out of sight
    0-5.4 %; in sight p95 0.033-0.053 m; in all p95 0.034-0.066 m; the error over its sigma at most
    1.69. With an 80 deg camera this flight's marker left the frame in the holdoff for 14-19 % of the
    approach, and its p95 read 0.07-0.24 m (docs/relnav.md, "Out of sight in the holdoff")."""
    from bench.relnav_replay import figures, replay

    directory = Path(px4_jobs["relnav"].result()["directory"])
    f = figures(directory, replay(directory, None, {}))
    assert f["replay_check_m_s"] == 0.0, f
    c = f["counts"]  # 0-13 markers rejected of 550-1350 a flight after the fix (10 flights and this test's)
    assert c["resets"] == 0 and c["markers_rejected"] <= 0.05 * c["markers_fused"], c
    a = f["approach"]
    assert a["blind_share"] <= 0.1, a
    assert a["in_sight_position_error_m"][1] <= 0.1 and a["position_error_m"][1] <= 0.2, a
    assert a["error_over_sigma"][2] <= 3.0, a
