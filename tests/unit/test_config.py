"""Configuration: every shipped config loads; a bad field is named with its value and rule."""
from __future__ import annotations

import subprocess
import sys

import pytest

from mission.config import from_dict, load_config, with_overrides
from mission.errors import ConfigError
from tests.conftest import CONFIGS


@pytest.mark.parametrize("path", sorted(CONFIGS.glob("*.toml")), ids=lambda p: p.name)
def test_shipped_configs_load(path):
    load_config(path)


@pytest.mark.parametrize("data,field,words", [
    ({"law": {"b": 0.9}}, "law.b", "greater than 1"),
    ({"law": {"k_c": -1}}, "law.k_c", "greater than 0"),
    ({"law": {"kc": 1}}, "law.kc", "unknown field"),
    ({"scenario": {"target": [1.0, 2.0]}}, "scenario.target", "3 components"),
    ({"scenario": {"target": [5.0, 0.0, 0.0]}}, "scenario.eta", "b*c"),
    ({"scenario": {"target": [40.0, 0.0, -9.0]}}, "scenario.target", "height"),
    ({"mission": {"rate_hz": 0}}, "mission.rate_hz", "greater than 0"),
    ({"mission": {"final_action": "crash"}}, "mission.final_action", "'hold' or 'land'"),
    ({"zenoh": {"pair": "a/b"}}, "zenoh.pair", "pattern"),
    ({"safety": {"margin_m": float("nan")}}, "safety.margin_m", "finite"),
])
def test_bad_fields_are_named(data, field, words):
    with pytest.raises(ConfigError) as exc:
        from_dict(data)
    assert exc.value.field == field
    assert words in str(exc.value)


def test_overrides_are_revalidated():
    cfg = from_dict({})
    assert with_overrides(cfg, {"mavlink.url": "udpin:127.0.0.1:1"}).mavlink.url == "udpin:127.0.0.1:1"
    with pytest.raises(ConfigError, match="mission.rate_hz"):
        with_overrides(cfg, {"mission.rate_hz": -5})


def test_cli_bad_config_exits_2_naming_the_field(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[law]\nb = 0.5\n")
    out = subprocess.run([sys.executable, "-m", "mission.cli", "simulate", str(bad)], capture_output=True, text=True)
    assert out.returncode == 2
    assert "law.b" in out.stderr and "0.5" in out.stderr


def test_cli_missing_and_broken_files_exit_2(tmp_path):
    out = subprocess.run([sys.executable, "-m", "mission.cli", "simulate", str(tmp_path / "nope.toml")], capture_output=True, text=True)
    assert out.returncode == 2 and "file not found" in out.stderr
    broken = tmp_path / "broken.toml"
    broken.write_text("[law\n")
    out = subprocess.run([sys.executable, "-m", "mission.cli", "simulate", str(broken)], capture_output=True, text=True)
    assert out.returncode == 2 and "not valid TOML" in out.stderr
