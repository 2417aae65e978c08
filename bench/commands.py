"""The benchmarks' ``marsupial`` subcommand, registered in ``pyproject.toml`` under the entry-point
group ``marsupial.commands`` (see :mod:`mission.cli.subcommands`)."""
from __future__ import annotations

from mission.cli.subcommands import Subcommand

bench = Subcommand("bench.__main__:bench", "Benchmarks: print a table and write JSON.")
