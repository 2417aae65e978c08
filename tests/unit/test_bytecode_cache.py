"""The commands a test starts keep their bytecode (``tests/conftest.py``): none of them compiles
the package from source again because the environment said not to write ``.pyc`` files."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from tests.conftest import keep_bytecode, user_cache


def test_no_bytecode_beside_the_sources_moves_it_to_the_cache(tmp_path: Path) -> None:
    env = {"PYTHONDONTWRITEBYTECODE": "1", "PATH": "/bin"}
    assert keep_bytecode(env, tmp_path)
    assert env == {"PYTHONPYCACHEPREFIX": str(tmp_path), "PATH": "/bin"}


def test_bytecode_written_anyway_or_a_chosen_prefix_is_left_alone(tmp_path: Path) -> None:
    for env in ({"PATH": "/bin"}, {"PYTHONDONTWRITEBYTECODE": "", "PATH": "/bin"},
                {"PYTHONDONTWRITEBYTECODE": "1", "PYTHONPYCACHEPREFIX": "/elsewhere"}):
        before = dict(env)
        assert not keep_bytecode(env, tmp_path)
        assert env == before


def test_a_command_started_by_a_test_writes_its_bytecode() -> None:
    out = subprocess.run([sys.executable, "-c", "import sys; print(sys.flags.dont_write_bytecode, sys.pycache_prefix)"],
                         capture_output=True, text=True, env=os.environ, check=True)
    dont_write, prefix = out.stdout.split()
    assert dont_write == "0"
    assert prefix == "None" or Path(prefix) == user_cache() or prefix == os.environ.get("PYTHONPYCACHEPREFIX")
