"""The mock vehicle's estimate: by default it errs as PX4 SITL's does, seeded; ``--ideal`` or
``--estimate-error 0`` make it exact (docs/mock-vehicle.md). The errors' clock starts at take-off."""
from __future__ import annotations

from typing import Any

import pytest
from click.testing import CliRunner

import sim.vehicle.cli as cli
from sim.vehicle.estimator import PX4_SITL_SCALE, EstimateError
from sim.vehicle.faults import FaultOptions
from sim.vehicle.options import VehicleOptions


def _options(monkeypatch: pytest.MonkeyPatch, *args: str) -> tuple[int, VehicleOptions | None, str]:
    """The options ``mock-vehicle ARGS`` would run with (the vehicle itself not started)."""
    got: dict[str, Any] = {}
    monkeypatch.setattr(cli, "run", lambda options, *a, **k: got.setdefault("options", options))
    result = CliRunner().invoke(cli.mock_vehicle, list(args))
    return result.exit_code, got.get("options"), result.output


def test_px4_sitls_errors_by_default_and_exact_when_asked(monkeypatch):
    assert VehicleOptions().estimate_error == PX4_SITL_SCALE == 1.0
    for args in (("--seed", "7"), ("--seed", "7", "--estimate-error", "1")):
        code, opts, _ = _options(monkeypatch, *args)
        assert code == 0 and opts is not None and cli.estimate_of(opts) == {"scale": 1.0, "seed": 7}, args
        assert cli.describe_estimate(opts) == "estimate errs 1x PX4 SITL's (seed 7)"
    for args in (("--ideal",), ("--estimate-error", "0"), ("--ideal", "--estimate-error", "0")):
        code, opts, _ = _options(monkeypatch, *args)
        assert code == 0 and opts is not None and opts.estimate_error == 0.0, args
        assert cli.describe_estimate(opts) == "exact estimate"
    code, opts, out = _options(monkeypatch, "--ideal", "--estimate-error", "0.5")
    assert code == 2 and opts is None and "--ideal is an exact estimate" in out
    rover = VehicleOptions(frame="rover")  # a rover's estimate is exact: the model is a multicopter's
    assert cli.estimate_of(rover)["scale"] == 0.0


def test_the_errors_are_seeded():
    def draw(seed: int) -> list[tuple[float, float, float]]:
        e = EstimateError(PX4_SITL_SCALE, seed=seed)
        out = []
        for _ in range(200):
            e.advance(0.005)
            out.append(e.velocity)
        return out
    assert draw(3) == draw(3) != draw(4)
    assert VehicleOptions(faults=FaultOptions(seed=3)).faults.seed == 3


def test_the_errors_clock_starts_at_take_off():
    """Before the first step flown the errors keep their first draw; from it they run, and the
    same seed gives the same errors counted from take-off, however long the start-up took."""
    def from_take_off(steps_on_the_ground: int) -> list[tuple[float, float, float]]:
        e = EstimateError(PX4_SITL_SCALE, seed=5)
        first = e.velocity
        for _ in range(steps_on_the_ground):
            e.advance(0.005, flown=False)
            assert e.velocity == first and not e.started
        out = []
        for k in range(100):
            e.advance(0.005, flown=k < 3)  # landed again: the clock keeps running
            out.append(e.velocity)
        return out
    flown = from_take_off(0)
    assert flown == from_take_off(250) and flown[0] != flown[-1]
