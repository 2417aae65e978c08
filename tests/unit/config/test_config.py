"""Configuration: every shipped config loads; a bad field is named with its value and rule."""
from __future__ import annotations

import subprocess
import sys

import pytest

from mission.config.schema import from_dict, load_config, with_overrides
from mission.errors import ConfigError
from tests.conftest import CONFIGS, FLIGHT_TOML


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
    ({"mission": {"rate_hz": 0}}, "mission.rate_hz", "greater than or equal to 10"),
    ({"mission": {"final_action": "crash"}}, "mission.final_action", "'hold', 'land' or 'return'"),
    ({"zenoh": {"pair": "a/b"}}, "zenoh.pair", "pattern"),
    ({"safety": {"margin_m": float("nan")}}, "safety.margin_m", "finite"),
    # riding on the deck: the deck above the floor (with room for the landing's press), the arming
    # lead longer than the prestream, the glide path inside the deck's keep-out
    ({"safety": {"z_max_m": -0.3}, "mission": {"ride": "deck", "dock_offset_ned_m": [0.0, 0.0, -0.35]}},
     "mission.dock_offset_ned_m", "altitude floor"),
    ({"mission": {"ride": "deck", "dock_offset_ned_m": [0.0, 0.0, -0.5], "prestream_s": 4.0, "arm_lead_s": 4.0}},
     "mission.arm_lead_s", "prestream_s"),
    ({"mission": {"ride": "deck", "dock_offset_ned_m": [0.0, 0.0, -0.5], "final_action": "return",
                  "deck_clear_slope": 2.0}}, "mission.deck_clear_slope", "glide"),
    ({"mission": {"ride": "carried"}}, "mission.ride", "'hover' or 'deck'"),
    ({"relnav": {"marker_timeout_s": 0.3, "descent_marker_timeout_s": 0.4}}, "relnav.descent_marker_timeout_s",
     "relnav.marker_timeout_s"),
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


# ---------------------------------------------------------------------------------- every rule of every field

def _rule_cases() -> list[tuple[str, object, str]]:
    """(dotted field, bad value, words of the rule) for every field of every section that has a
    rule: numeric bounds, choices (Literal), patterns, finiteness of floats, types."""
    import math
    import types
    import typing

    from annotated_types import Ge, Gt, Le, Lt, MaxLen, MinLen

    from mission.config.schema import Config

    cases: list[tuple[str, object, str]] = []
    for section, sfield in Config.model_fields.items():
        for name, f in sfield.annotation.model_fields.items():  # type: ignore[union-attr]
            dotted = f"{section}.{name}"
            origin = typing.get_origin(f.annotation)
            optional = origin in (typing.Union, types.UnionType)
            args = typing.get_args(f.annotation) if optional else ()
            base = next((a for a in (f.annotation, *args) if a in (int, float, bool, str)), None)
            if origin in (list, tuple) and float in typing.get_args(f.annotation):
                cases.append((dotted, [math.nan, 1.0, 2.0][: len(typing.get_args(f.annotation)) if origin is tuple else 3],
                              "finite"))
            for m in f.metadata:
                if isinstance(m, Gt):
                    cases.append((dotted, m.gt, f"greater than {m.gt}"))
                elif isinstance(m, Ge):
                    cases.append((dotted, m.ge - (1 if base is int else 0.05), f"greater than or equal to {m.ge}"))
                elif isinstance(m, Le):
                    cases.append((dotted, m.le + 1, f"less than or equal to {m.le}"))
                elif isinstance(m, Lt):
                    cases.append((dotted, m.lt, f"less than {m.lt}"))
                elif isinstance(m, MaxLen):
                    if origin is list:
                        item = {"center": [0.0, 0.0, 0.0], "radius": 1.0} if name == "obstacles" else "tcp/127.0.0.1:1"
                        cases.append((dotted, [item] * (m.max_length + 1), f"at most {m.max_length} items"))
                    else:
                        cases.append((dotted, "a" * (m.max_length + 1), f"at most {m.max_length} characters"))
                elif isinstance(m, MinLen):
                    cases.append((dotted, "", f"at least {m.min_length} character"))
                elif getattr(m, "pattern", None):
                    cases.append((dotted, "a/b c", "pattern"))
            if typing.get_origin(f.annotation) is typing.Literal:
                cases.append((dotted, "no-such-choice", "Input should be"))
            if base is float:
                cases.append((dotted, math.nan, "finite"))
                cases.append((dotted, "fast", "valid number"))
            elif base is int:
                cases.append((dotted, 2.5, "valid integer"))
            elif base is bool:
                cases.append((dotted, [1], "valid boolean"))
            elif base is str:
                cases.append((dotted, 7, "valid string"))
    return cases


RULE_CASES = _rule_cases()


def test_rule_table_covers_every_constrained_field():
    from mission.config.schema import Config

    constrained = {f"{s}.{n}" for s, sf in Config.model_fields.items() for n, f in sf.annotation.model_fields.items()  # type: ignore[union-attr]
                   if f.metadata}
    covered = {field for field, _, _ in RULE_CASES}
    assert constrained <= covered and len(RULE_CASES) > 100


@pytest.mark.parametrize("field,value,words", RULE_CASES, ids=[f"{f}={v!r}" for f, v, _ in RULE_CASES])
def test_every_rule_names_field_value_and_rule(field, value, words):
    section, name = field.split(".")
    with pytest.raises(ConfigError) as exc:
        from_dict({section: {name: value}})
    assert exc.value.field == field or exc.value.field.startswith(field + "[")  # a list item: field[<index>]
    assert words in str(exc.value)
    shown = value[0] if isinstance(value, list) else value  # the value, as given (the bad item of a list)
    assert repr(shown) in str(exc.value) or str(shown) in str(exc.value)


def _run_cli_sending_to(tmp_path, config_text: str, *extra: str) -> tuple[int, str, list[bytes]]:
    """``marsupial run`` pointed at a UDP socket where the vehicle would be (udpout: the mission
    talks first); returns its exit code, stderr and the datagrams that reached the socket."""
    import select
    import socket

    cfg = tmp_path / "run.toml"
    cfg.write_text(config_text)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as vehicle:
        vehicle.bind(("127.0.0.1", 0))
        port = vehicle.getsockname()[1]
        proc = subprocess.Popen([sys.executable, "-m", "mission.cli", "run", str(cfg), "--mavlink", f"udpout:127.0.0.1:{port}",
                                 "--zenoh-listen", "tcp/127.0.0.1:0", "--log-dir", str(tmp_path / "log"), *extra],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            got: list[bytes] = []
            while proc.poll() is None and not got:
                if select.select([vehicle], [], [], 0.05)[0]:
                    got.append(vehicle.recv(65535))
            proc.terminate()
            _, err = proc.communicate(timeout=20)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        vehicle.setblocking(False)
        while True:  # the process is gone: whatever it sent is in the socket now
            try:
                got.append(vehicle.recv(65535))
            except BlockingIOError:
                break
    return proc.returncode, err, got


def test_run_with_a_bad_config_exits_2_and_sends_nothing(tmp_path):
    code, err, got = _run_cli_sending_to(tmp_path, FLIGHT_TOML + "[mission]\nrate_hz = -50\n")
    assert code == 2 and "mission.rate_hz" in err and "-50" in err and got == []
    code, err, got = _run_cli_sending_to(tmp_path, FLIGHT_TOML + "[mavlink]\nsigning_key_file = \"/nonexistent/key\"\n")
    assert code == 2 and "mavlink.signing_key_file" in err and got == []
    code, err, got = _run_cli_sending_to(tmp_path, FLIGHT_TOML + "[zenoh]\nsigning_key_file = \"/nonexistent/key\"\n")
    assert code == 2 and "zenoh.signing_key_file" in err and got == []
    code, err, got = _run_cli_sending_to(tmp_path, FLIGHT_TOML, "--pair", "no/slash")
    assert code == 2 and "zenoh.pair" in err and got == []
    # an empty file states no target and no limits: refused (on main it flew to a default target)
    code, err, got = _run_cli_sending_to(tmp_path, "")
    assert code == 2 and "error: scenario.target = None: the file has no [scenario] section" in err and got == []
    # control: with a good configuration the same socket does hear the mission (its HEARTBEAT)
    code, err, got = _run_cli_sending_to(tmp_path, FLIGHT_TOML)
    assert got, err
