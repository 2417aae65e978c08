"""The layers point one way: every import goes down the layer table of docs/how-it-works.md (read
from the page itself, so the page and the check cannot drift apart), mission/ has no import
circle, the product (mission/) imports nothing from the simulator or the benchmarks and still
offers their subcommands through the registry."""
from __future__ import annotations

import ast
import re
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


LAYER_DOC = ROOT / "docs" / "how-it-works.md"
LAYER_NAMES = ["tools", "simulator", "product wiring", "interfaces", "I/O adapters", "clocks", "pure core"]
TOPS = ("mission", "sim", "bench", "tests")


def layer_table(text: str) -> list[tuple[str, list[str]]]:
    """The rows of the table under ``## Layers`` in ``text``, top layer first: (name, the paths
    the row names: every backticked ``mission/``, ``sim/``, ``bench/`` or ``tests/`` file or folder)."""
    section = text.split("\n## Layers\n", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("|")][2:]  # past the header and |---|
    table = []
    for row in rows:
        name, modules = (cell.strip() for cell in row.strip("|").split("|")[:2])
        table.append((name, [p for p in re.findall(r"`([^`]+)`", modules) if p.split("/")[0] in TOPS and "/" in p]))
    return table


def layer_of(path: str, table: list[tuple[str, list[str]]]) -> int | None:
    """The index in ``table`` of the row naming the file ``path`` (relative to the repository) or,
    failing that, its nearest folder; None: no row names it."""
    best: tuple[int, int] | None = None
    for index, (_, paths) in enumerate(table):
        for p in paths:
            if path == p or (p.endswith("/") and path.startswith(p)):
                if best is None or len(p) > best[1]:
                    best = (index, len(p))
    return None if best is None else best[0]


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_edges(files: list[Path]) -> dict[str, dict[str, int]]:
    """{module: {a module of ``files`` it imports: the line}}, for every import of the file: at
    the top, inside a function or under ``if TYPE_CHECKING`` alike. ``from package import name``
    is an import of the submodule ``package.name`` when there is one, else of the package."""
    modules = {module_name(p): p for p in files}

    def resolve(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    edges: dict[str, dict[str, int]] = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        found: dict[str, int] = {}
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:  # relative: from the package, up level - 1
                    parts = package.split(".")
                    base = ".".join([*parts[:len(parts) - node.level + 1], *filter(None, [base])])
                targets = [f"{base}.{alias.name}" for alias in node.names]
            else:
                continue
            for target in targets:
                hit = resolve(target)
                if hit is not None and hit != name:
                    found.setdefault(hit, node.lineno)
        edges[name] = found
    return edges


def upward_imports(files: list[Path], table: list[tuple[str, list[str]]]) -> list[str]:
    """Every import in ``files`` of a module of a layer above the importer's ("a.b (layer) ->
    c.d (layer above), line n")."""
    layers = {module_name(p): layer_of(str(p.relative_to(ROOT)), table) for p in files}
    found = []
    for importer, imported in import_edges(files).items():
        for target, line in imported.items():
            mine, theirs = layers[importer], layers[target]
            if mine is not None and theirs is not None and theirs < mine:
                found.append(f"{importer} ({table[mine][0]}) -> {target} ({table[theirs][0]}), line {line}")
    return sorted(found)


def cycles(edges: dict[str, dict[str, int]]) -> list[list[str]]:
    """The import circles of ``edges``: each strongly connected set of more than one module, sorted
    (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in edges:
                    continue
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                members = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    members.append(member)
                    if member == node:
                        break
                if len(members) > 1:
                    found.append(sorted(members))
    return sorted(found)


def _our_files() -> list[Path]:
    return [p for top in TOPS for p in sorted((ROOT / top).rglob("*.py"))]


def test_the_layer_table_is_read_from_the_docs_and_names_what_exists():
    table = layer_table(LAYER_DOC.read_text())
    assert [name for name, _ in table] == LAYER_NAMES
    named = [p for _, paths in table for p in paths]
    assert "mission/core/" in named and "mission/interfaces.py" in named
    assert [p for p in named if not (ROOT / p).exists()] == []  # the page names no module that is gone


def test_every_module_has_a_layer():
    table = layer_table(LAYER_DOC.read_text())
    files = [str(p.relative_to(ROOT)) for p in _our_files() if p != ROOT / "mission" / "__init__.py"]  # (empty)
    assert [f for f in files if layer_of(f, table) is None] == []


def test_imports_point_down_the_layer_table():
    """Every edge of the table: no module imports one of a layer above its own, not even for a
    type annotation (the reader and the type checker still need the other layer)."""
    assert upward_imports(_our_files(), layer_table(LAYER_DOC.read_text())) == []


def test_the_layer_check_can_fail(tmp_path, monkeypatch):
    table = [("top", ["pkg/top.py"]), ("bottom", ["pkg/"])]
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "top.py").write_text("from . import low\n")  # a relative import too
    (tmp_path / "pkg" / "low.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.top import X\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    files = sorted((tmp_path / "pkg").glob("*.py"))
    assert import_edges(files) == {"pkg.low": {"pkg.top": 3}, "pkg.top": {"pkg.low": 1}}
    assert upward_imports(files, table) == ["pkg.low (bottom) -> pkg.top (top), line 3"]
    assert (layer_of("pkg/top.py", table), layer_of("pkg/low.py", table), layer_of("x/y.py", table)) == (0, 1, None)


def test_mission_has_no_import_circle():
    """No module of mission/ imports itself back through others, counting every import: at the
    top, inside a function and under ``if TYPE_CHECKING`` (a circle of type-only imports still
    means neither module can be read, changed or moved without the other)."""
    assert cycles(import_edges(sorted((ROOT / "mission").rglob("*.py")))) == []


def test_the_circle_check_can_fail():
    edges = {"a": {"b": 1}, "b": {"c": 1}, "c": {"a": 1, "d": 1}, "d": {}, "e": {"e": 1, "f": 1}, "f": {"e": 1}}
    assert cycles(edges) == [["a", "b", "c"], ["e", "f"]]


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
PURE_PACKAGES = ("mission/core", "mission/phases", "mission/config", "mission/passenger", "mission/vision")
PURE = tuple(sorted(
    {".".join(p.relative_to(ROOT).with_suffix("").parts) for d in PURE_PACKAGES for p in (ROOT / d).glob("*.py")
     if p.name != "__init__.py" and p.relative_to(ROOT).as_posix() != "mission/vision/capture.py"}  # the camera: I/O
    | {"mission.bus.wire", "mission.bus.ros2", "mission.bus.gate", "mission.flight_mode", "mission.carrier.modes",
       "mission.carrier.guard", "mission.carrier.tracking", "mission.carrier.start", "mission.carrier.acceleration",
       "mission.carrier.backends", "mission.carrier.step", "mission.carrier.backends.sim", "mission.bus.encodings",
       "mission.carrier.heard",
       "sim.batch.closed_loop"}))
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
           "mission.phases.machine", "mission.phases.flying", "mission.phases.types", "mission.controller",
           "mission.passenger.step")
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
