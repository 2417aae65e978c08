"""The mock vehicle's estimate: exact by default; with ``--estimate-error 1`` it errs as PX4 SITL's
does, seeded (docs/mock-vehicle.md, "How close to PX4": why the default is not yet PX4's)."""
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


def test_exact_by_default_and_px4_sitls_errors_when_asked(monkeypatch):
    assert VehicleOptions().estimate_error == 0.0 and PX4_SITL_SCALE == 1.0
    code, opts, _ = _options(monkeypatch, "--seed", "7")
    assert code == 0 and opts is not None and cli.describe_estimate(opts) == "exact estimate"
    code, opts, _ = _options(monkeypatch, "--seed", "7", "--estimate-error", "1")
    assert code == 0 and opts is not None and cli.estimate_of(opts) == {"scale": 1.0, "seed": 7}
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
