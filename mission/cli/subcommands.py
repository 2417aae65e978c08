"""Subcommands of ``marsupial`` that other packages register (the simulator's, the benchmarks').

A package declares a :class:`Subcommand` object and names it in ``pyproject.toml`` under the
entry-point group ``marsupial.commands``; :func:`registered` finds them, so the product's CLI
(:mod:`mission.cli`) never names the simulator's modules. :func:`entry_points` reads any group
(the measurement feeds' ``marsupial.feeds`` and the simulation's ``marsupial.sensors`` too). Run from a source tree that is not
installed, the same table is read from ``pyproject.toml`` beside the package.
"""
from __future__ import annotations

import importlib
import importlib.metadata
import tomllib
from dataclasses import dataclass
from pathlib import Path

import click

ENTRY_POINT_GROUP = "marsupial.commands"


@dataclass(frozen=True)
class Subcommand:
    """A lazily imported subcommand: ``target`` is ``"module:attribute"`` of a ``click.Command``;
    ``summary`` is its line in ``marsupial --help`` (shown without importing it)."""

    target: str
    summary: str

    def load(self) -> click.Command:
        module, _, attr = self.target.partition(":")
        return getattr(importlib.import_module(module), attr)


#: Entry points: the simulation's sensor standing in for the measurement feed of the same name
#: (:mod:`sim.batch.sensors`).
SENSORS_GROUP = "marsupial.sensors"


def entry_points(group: str = ENTRY_POINT_GROUP) -> dict[str, str]:
    """name -> ``"module:attribute"`` of the entry-point ``group``: from ``pyproject.toml`` beside
    the package when running from a source tree (in declaration order), else from the installed
    distribution's entry points."""
    pyproject = Path(__file__).resolve().parents[2] / "pyproject.toml"  # mission/cli/ -> the source tree
    if pyproject.is_file():
        table = tomllib.loads(pyproject.read_text()).get("project", {}).get("entry-points", {})
        return dict(table.get(group, {}))
    return {ep.name: ep.value for ep in importlib.metadata.entry_points(group=group)}


def load(target: str) -> object:
    """The object a ``"module:attribute"`` target names (its module imported)."""
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)


def registered() -> dict[str, Subcommand]:
    """Every registered subcommand by name (imports only the small modules that declare them)."""
    found: dict[str, Subcommand] = {}
    for name, value in entry_points().items():
        spec = load(value)
        if not isinstance(spec, Subcommand):
            raise TypeError(f"entry point {ENTRY_POINT_GROUP}:{name} = {value!r} is not a Subcommand")
        found[name] = spec
    return found
