"""The configuration reference: every field documented with a unit, docs/configuration.md in step."""
from __future__ import annotations

import re

from click.testing import CliRunner

from mission.cli.config import config_command
from mission.config.reference import fields, markdown_table
from tests.conftest import CONFIGS, ROOT


def test_every_field_has_a_meaning_with_a_unit():
    rows = fields()
    assert len(rows) > 60
    missing = [r["key"] for r in rows if not re.match(r"^\[[^\]]+\] \S", r["doc"])]
    assert not missing, ("fields without a '[unit] meaning' doc: add description='[unit] ...' to the Field in "
                         f"mission/config/: {missing}")


def test_documented_table_is_the_generated_one():
    text = (ROOT / "docs" / "configuration.md").read_text()
    start, end = "<!-- config-reference:start -->\n", "\n<!-- config-reference:end -->"
    assert text.count(start) == 1 and text.count(end) == 1, "docs/configuration.md: one pair of config-reference markers"
    block = text.split(start, 1)[1].split(end, 1)[0]
    assert block == markdown_table(), ("docs/configuration.md out of step: paste `marsupial config --markdown` "
                                       "between the markers")


def test_config_command_prints_reference_schema_and_effective_values():
    runner = CliRunner()
    out = runner.invoke(config_command, [], standalone_mode=False).output
    assert "mission.connect_timeout_s  (float, default 20.0, > 0, <= 600)" in out and "[s] how long `run` waits" in out
    assert '"$defs"' in runner.invoke(config_command, ["--schema"], standalone_mode=False).output
    eff = runner.invoke(config_command, [str(CONFIGS / "demo.toml")], standalone_mode=False).output
    assert "scenario.target = [24.0, 18.0, -5.0]" in eff and "mission.connect_timeout_s = 20.0" in eff
