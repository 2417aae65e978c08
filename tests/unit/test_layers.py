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


MAX_MODULE_LINES = 600  # a smell detector, not a shape-giver: folders give the shape
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


def test_no_module_over_600_lines_and_no_class_over_300():
    names = [str(p.relative_to(ROOT)) for top in ("mission", "sim", "bench") for p in sorted((ROOT / top).rglob("*.py"))]
    assert len(names) > 50
    assert [f for name in names if name not in SIZE_EXEMPT for f in oversized(name, (ROOT / name).read_text())] == []


def test_the_size_guard_can_fail():
    fits = "class Small:\n" + "    x = 1\n" * (MAX_CLASS_LINES - 1) + "y = 2\n" * (MAX_MODULE_LINES - MAX_CLASS_LINES)
    assert oversized("fits.py", fits) == []
    big = "class Big:\n" + "    x = 1\n" * MAX_CLASS_LINES + "y = 2\n" * (MAX_MODULE_LINES - MAX_CLASS_LINES)
    assert oversized("big.py", big) == [f"big.py: {MAX_MODULE_LINES + 1} lines", f"big.py: class Big {MAX_CLASS_LINES + 1} lines"]


# The pure parts: loading them imports no I/O (a function may still import what it needs when
# called, e.g. the config's key-expression check asks Zenoh's parser). Whole packages, and the pure
# modules of the packages that also hold I/O.
PURE_PACKAGES = ("mission/core", "mission/phases", "mission/config")
PURE = tuple(sorted(
    {".".join(p.relative_to(ROOT).with_suffix("").parts) for d in PURE_PACKAGES for p in (ROOT / d).glob("*.py")
     if p.name != "__init__.py"}
    | {"mission.bus.wire", "mission.bus.ros2", "mission.bus.gate", "mission.flight_mode", "mission.carrier.modes",
       "mission.carrier.guard", "mission.carrier.tracking", "mission.carrier.start", "mission.carrier.acceleration",
       "mission.carrier.backends", "sim.batch.closed_loop"}))
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


def test_the_pure_list_is_not_empty():
    assert "mission.core.law" in PURE and "mission.phases.machine" in PURE and "mission.config.schema" in PURE


def _package_imports(top: str) -> dict[str, set[str]]:
    """{module under ``top``: the modules of mission/sim/bench it imports anywhere}."""
    out = {}
    for p in sorted((ROOT / top).rglob("*.py")):
        name = ".".join(p.relative_to(ROOT).with_suffix("").parts)
        out[name] = {m for m in imported_modules(p) if m.split(".")[0] in ("mission", "sim", "bench")}
    return out


def test_core_imports_only_core():
    """The law, the safety filter and the tracking loop stand alone: they import nothing of ours but
    each other and the error hierarchy."""
    bad = {m: sorted(i for i in imps if not i.startswith("mission.core") and i != "mission.errors")
           for m, imps in _package_imports("mission/core").items()}
    assert {m: v for m, v in bad.items() if v} == {}


def test_io_packages_know_nothing_of_the_law():
    """MAVLink, the bus, time and the mock vehicle move bytes: they import no law, safety filter,
    tick, tracking or phase machine (frames from mission.core.geodesy and the phase names are data)."""
    law = ("mission.core.law", "mission.core.safety", "mission.core.tick", "mission.core.tracking",
           "mission.phases.machine", "mission.phases.flying", "mission.phases.types", "mission.controller")
    bad = {}
    for top in ("mission/mavlink", "mission/bus", "mission/time", "sim/vehicle"):
        for m, imps in _package_imports(top).items():
            hits = sorted(i for i in imps if i.startswith(law))
            if hits:
                bad[m] = hits
    assert bad == {}


def test_test_aids_are_used_only_by_tests_and_benches():
    """sim.testing (fake PX4, probe) and sim.sitl (the PX4 SITL harness) serve tests and benches;
    the product and the simulator's commands never import them."""
    aids = ("sim.testing", "sim.sitl")
    bad = {}
    for top in ("mission", "sim"):
        for m, imps in _package_imports(top).items():
            if m.startswith(aids):
                continue
            hits = sorted(i for i in imps if i.startswith(aids))
            if hits:
                bad[m] = hits
    assert bad == {}


MAX_MODULES_PER_FOLDER = 15
MAX_TOP_MODULES = 12  # the top of mission/: the loop, its wiring and the record
MAX_SHARED_PREFIX = 3  # four modules named prefix_*: a package hiding in a folder


def folder_problems(folders: dict[str, list[str]], top: str) -> list[str]:
    """What is wrong with the layout ``folders`` ({folder: its module file names}): too many
    modules in a folder (``top`` has its own limit), or a name prefix shared by too many."""
    found = []
    for folder, names in folders.items():
        modules = [n for n in names if n != "__init__.py" and n != "__main__.py"]
        limit = MAX_TOP_MODULES if folder == top else MAX_MODULES_PER_FOLDER
        if len(modules) > limit:
            found.append(f"{folder}: {len(modules)} modules (at most {limit})")
        prefixes: dict[str, int] = {}
        for n in modules:
            if "_" in n:
                prefixes[n.split("_")[0]] = prefixes.get(n.split("_")[0], 0) + 1
        found += [f"{folder}: {count} modules named {prefix}_*" for prefix, count in prefixes.items()
                  if count > MAX_SHARED_PREFIX]
    return found


def test_folders_show_the_concepts():
    folders: dict[str, list[str]] = {}
    for top in ("mission", "sim"):
        for p in sorted((ROOT / top).rglob("*.py")):
            folders.setdefault(str(p.parent.relative_to(ROOT)), []).append(p.name)
    assert folder_problems(folders, "mission") == []


def test_the_folder_guard_can_fail():
    crowded = {"mission": [f"m{i}.py" for i in range(MAX_TOP_MODULES + 1)],
               "sim/x": ["vehicle_a.py", "vehicle_b.py", "vehicle_c.py", "vehicle_d.py", "__init__.py"]}
    assert folder_problems(crowded, "mission") == [f"mission: {MAX_TOP_MODULES + 1} modules (at most {MAX_TOP_MODULES})",
                                                   "sim/x: 4 modules named vehicle_*"]
