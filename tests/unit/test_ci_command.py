"""CI runs the README's test command: the two must stay in step (a new user runs what CI runs)."""
from __future__ import annotations

from tests.conftest import ROOT


def test_ci_runs_the_readme_test_command() -> None:
    readme = (ROOT / "README.md").read_text().splitlines()
    install = readme[readme.index("# 2. install and run the tests") + 1]
    prefix = "python3 -m venv .venv && .venv/bin/pip install -e '.[test]' && "
    assert install.startswith(prefix), install
    ci = [line for line in (ROOT / ".ci" / "run").read_text().splitlines() if line and not line.startswith("#")]
    assert ci[-1] == install[len(prefix):]
    alone = "tests/faults/test_stall_faults.py tests/px4_sitl"  # real-time flights that need the machine, after
    assert "--ignore=tests/px4_sitl --ignore=tests/faults/test_stall_faults.py" in ci[-1] and ci[-1].endswith(f"pytest {alone}")
