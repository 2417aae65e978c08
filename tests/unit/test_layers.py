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
    code = ("import sys, mission.cli, mission.cli.run, mission.controller, mission.mavlink.link, mission.bus.bridge; "
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


MAX_MODULE_LINES = 500
MAX_CLASS_LINES = 300
SIZE_EXEMPT: set[str] = set()  # none: every module and class fits


def oversized(name: str, text: str) -> list[str]:
    """What is too big in the source ``text`` of file ``name``: the module (over MAX_MODULE_LINES)
    and its classes (over MAX_CLASS_LINES, from the ``class`` line to the body's last line)."""
    lines = len(text.splitlines())
    found = [f"{name}: {lines} lines"] if lines > MAX_MODULE_LINES else []
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.ClassDef):
            size = (node.end_lineno or node.lineno) - node.lineno + 1
            if size > MAX_CLASS_LINES:
                found.append(f"{name}: class {node.name} {size} lines")
    return found


def test_no_module_over_500_lines_and_no_class_over_300():
    names = [str(p.relative_to(ROOT)) for top in ("mission", "sim", "bench") for p in sorted((ROOT / top).rglob("*.py"))]
    assert len(names) > 50
    assert [f for name in names if name not in SIZE_EXEMPT for f in oversized(name, (ROOT / name).read_text())] == []


def test_the_size_guard_can_fail():
    fits = "class Small:\n" + "    x = 1\n" * (MAX_CLASS_LINES - 1) + "y = 2\n" * (MAX_MODULE_LINES - MAX_CLASS_LINES)
    assert oversized("fits.py", fits) == []
    big = "class Big:\n" + "    x = 1\n" * MAX_CLASS_LINES + "y = 2\n" * (MAX_MODULE_LINES - MAX_CLASS_LINES)
    assert oversized("big.py", big) == [f"big.py: {MAX_MODULE_LINES + 1} lines", f"big.py: class Big {MAX_CLASS_LINES + 1} lines"]


# The pure core: loading it imports no I/O (a function may still import what it needs when called,
# e.g. the config's key-expression check asks Zenoh's parser).
PURE = ("mission.core.law", "mission.core.safety", "mission.core.tick", "mission.core.tracking", "mission.phases", "mission.phases.types",
        "mission.phases.flying", "mission.bus.gate", "mission.bus.wire", "mission.config.schema", "sim.batch.closed_loop")
IO_MODULES = {"socket", "select", "selectors", "threading", "time", "subprocess", "signal", "asyncio", "zenoh",
              "pymavlink", "serial"}


def module_level_imports(path: Path) -> set[str]:
    """Modules a file imports when it is loaded: not inside functions, not under ``if TYPE_CHECKING``."""
    names: set[str] = set()

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                continue
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                continue
            if isinstance(child, ast.Import):
                names.update(alias.name for alias in child.names)
            elif isinstance(child, ast.ImportFrom) and child.module and child.level == 0:
                names.add(child.module)
                names.update(f"{child.module}.{alias.name}" for alias in child.names)  # a submodule, maybe
            visit(child)

    visit(ast.parse(path.read_text()))
    return names


def io_loaded_by(module: str) -> dict[str, list[str]]:
    """{our module: the I/O modules it imports} over everything ``module`` loads of mission/ and sim/."""
    found: dict[str, list[str]] = {}
    seen: set[str] = set()
    todo = [module]
    while todo:
        name = todo.pop()
        path = next((p for p in (ROOT / (name.replace(".", "/") + ".py"), ROOT / name.replace(".", "/") / "__init__.py")
                     if p.exists()), None)
        if name in seen or path is None:
            continue
        seen.add(name)
        imports = module_level_imports(path)
        io = sorted(m for m in imports if m.split(".")[0] in IO_MODULES)
        if io:
            found[name] = io
        todo += [m for m in imports if m.split(".")[0] in ("mission", "sim")]
    return found


def test_the_pure_core_loads_no_io():
    assert {m: io_loaded_by(m) for m in PURE if io_loaded_by(m)} == {}
    assert io_loaded_by("mission.mavlink.link")  # the check can see I/O: the link is made of it
