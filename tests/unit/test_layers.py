"""The layers point one way: the product (mission/) imports nothing from the simulator or the
benchmarks, and still offers their subcommands through the registry."""
from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import click
from click.testing import CliRunner

from mission.cli import PRODUCT, cli, subcommands

ROOT = Path(__file__).resolve().parents[2]


def imported_modules(path: Path) -> set[str]:
    """Every module a file imports, at the top or inside a function."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def test_mission_imports_nothing_from_sim_or_bench():
    offenders = {str(p.relative_to(ROOT)): sorted(m for m in imported_modules(p) if m.split(".")[0] in ("sim", "bench"))
                 for p in sorted((ROOT / "mission").rglob("*.py"))}
    assert {k: v for k, v in offenders.items() if v} == {}


def test_flying_loads_no_simulator_module():
    code = ("import sys, mission.cli, mission.run_cli, mission.controller, mission.link, mission.carrier_bridge; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('sim', 'bench')))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_every_subcommand_resolves_and_is_listed():
    specs = subcommands()
    assert set(PRODUCT) <= set(specs)
    assert {"simulate", "mock-vehicle", "demo", "bench"} <= set(specs)  # registered by sim/ and bench/
    for name, spec in specs.items():
        assert isinstance(spec.load(), click.Command), name
        assert spec.summary
    help_text = CliRunner().invoke(cli, ["--help"]).output
    for name in specs:
        assert f"  {name} " in help_text
