"""Hostile configuration files: >= 200 mutations of configs/demo.toml. Every one must be refused
at load with the mutated field named (``ConfigError``), before anything is opened.

Each mutation goes through the checks ``marsupial run`` makes before it opens anything
(``check_config(load_config(path))``, in process, a few ms each); one in :data:`CLI_EVERY`
also goes through ``marsupial run`` itself in process (exit 2, the field on stderr, no traceback,
no log directory), and three through the real process.

Mutations are written as TOML text (what a user types), one per file: wrong types (strings and
booleans as numbers, fractions as integers, tables as scalars), non-finite and absurd numbers
(1e300 timeouts, 0.001 Hz rates), bad URLs, ports, Zenoh endpoints and key expressions, control
characters and over-long strings, broken geometry across fields, and broken files (not UTF-8,
not TOML, a directory, a name too long).
"""
from __future__ import annotations

import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

from mission.cli import main
from mission.config.schema import load_config
from mission.errors import ConfigError
from mission.cli.run import check_config
from tests.conftest import CONFIGS

DEMO = (CONFIGS / "demo.toml").read_text()
RECOVERY = (CONFIGS / "recovery.toml").read_text()

# Numeric fields of demo.toml and of the sections' defaults: (section, key, is_int)
NUMERIC = [
    ("law", k, False) for k in ("k_c", "k_p", "b", "c", "d", "departure_margin_m")
] + [
    ("safety", k, False) for k in ("cbf_gain", "margin_m", "passenger_max_speed_m_s", "passenger_max_accel_m_s2",
                                   "carrier_max_speed_m_s", "carrier_max_accel_m_s2", "z_min_m", "z_max_m")
] + [
    ("sim", k, False) for k in ("dt_s", "duration_s", "p1_tolerance_m", "p2_tolerance_m")
] + [
    ("mission", k, False) for k in ("rate_hz", "dock_tolerance_m", "track_gain", "join_speed_m_s", "arrival_radius_m",
                                    "arrival_dwell_s", "carrier_timeout_s", "heartbeat_timeout_s", "prestream_s",
                                    "max_duration_s", "connect_timeout_s")
] + [("mission", "command_retries", True), ("scenario", "eta", False),
     ("mavlink", "target_system", True), ("mavlink", "target_component", True), ("mavlink", "source_system", True),
     ("mavlink", "source_component", True), ("carrier", "rate_hz", False), ("carrier", "max_speed_m_s", False),
     ("carrier", "passenger_timeout_s", False)]

BAD_FOR_NUMBERS = ['"1.0"', "true", "nan", "inf", "-inf", "1e300", "-1e300", "[1.0]", "{ x = 1 }"]
BAD_FOR_INTS = ["2.5", '"1"', "false", "1e300", "-1", "256"]
BAD_FOR_VECTORS = ['[0.0, "0", 0.0]', "[0.0, true, 0.0]", "[0.0, nan, 0.0]", "[1e300, 0.0, 0.0]", "[0.0, 0.0]",
                   '"0,0,0"', "[]", "[0.0, 0.0, 0.0, 0.0]"]


def mutated(section: str, key: str, raw: str) -> str:
    """demo.toml with ``key = raw`` in ``[section]`` (replacing the key's line if present)."""
    return mutated_text(DEMO, section, key, raw)


def mutated_text(text: str, section: str, key: str, raw: str) -> str:
    """The configuration ``text`` with ``key = raw`` in ``[section]`` (replacing the key's line if present)."""
    lines = text.splitlines()
    try:
        start = lines.index(f"[{section}]")
    except ValueError:
        return text + f"\n[{section}]\n{key} = {raw}\n"
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("[")), len(lines))
    for i in range(start + 1, end):
        if re.match(rf"{re.escape(key)}\s*=", lines[i]):
            lines[i] = f"{key} = {raw}"
            break
    else:
        lines.insert(start + 1, f"{key} = {raw}")
    return "\n".join(lines) + "\n"


def _cases() -> list[tuple[str, str, str]]:
    """(id, TOML text, the field the error must name)."""
    cases: list[tuple[str, str, str]] = []

    def add(section: str, key: str, raw: str, field: str | None = None) -> None:
        cases.append((f"{section}.{key}={raw}", mutated(section, key, raw), field or f"{section}.{key}"))

    for section, key, is_int in NUMERIC:
        for raw in BAD_FOR_INTS if is_int else BAD_FOR_NUMBERS:
            add(section, key, raw)
    for key in ("carrier_start", "target", "passenger_start"):
        for raw in BAD_FOR_VECTORS:
            add("scenario", key, raw)
    for raw in BAD_FOR_VECTORS:
        add("mission", "dock_offset_ned_m", raw)
    # absurd but finite values that would switch a failsafe off or stall the loop
    for section, key, raw in [("mission", "carrier_timeout_s", "1e3"), ("mission", "heartbeat_timeout_s", "3600"),
                              ("mission", "connect_timeout_s", "1e9"), ("mission", "rate_hz", "0.001"),
                              ("mission", "rate_hz", "1"), ("carrier", "rate_hz", "0.5"),
                              ("law", "departure_margin_m", "1e-300"), ("law", "departure_margin_m", "8.0"),
                              ("safety", "margin_m", "1e9"), ("mission", "max_duration_s", "1e12"),
                              ("mission", "command_retries", "1000000"), ("law", "b", "1.0")]:
        add(section, key, raw)
    # strings: URLs, ports, endpoints, key expressions, choices, lengths, control characters
    for raw in ['"bogus"', '"udpin:127.0.0.1:99999"', '"udpin:127.0.0.1:-1"', '"udpout:127.0.0.1:0"', '"tcp:host"',
                '"tcp:127.0.0.1:http"', '"udp:"', '""', '"/dev/ttyACM0:fast"', '"ftp://x"', "14540", "true",
                '"' + "u" * 300 + '"']:
        add("mavlink", "url", raw)
    for raw in ['"a/b"', '"a b"', '"*"', '""', '"pair#0"', '"' + "p" * 65 + '"', "7", '"p\\u0000"', '"p?x"', '"$*"']:
        add("zenoh", "pair", raw)
    for raw in ['"a//b"', '"/a"', '"a/"', '"a#b"', '"a?b"', '""', "1"]:
        add("zenoh", "carrier_key", raw)
    for key in ("listen", "connect"):
        for raw in ['["tcp/127.0.0.1:99999"]', '["bogus"]', '["tcp/127.0.0.1"]', '["tcp/:7447"]', '"tcp/127.0.0.1:7447"',
                    "[7447]", '["tcp/127.0.0.1:x"]']:
            add("zenoh", key, raw)
    add("zenoh", "connect", '["tcp/127.0.0.1:0"]')
    add("zenoh", "rendezvous", '"tcp/127.0.0.1:70000"')
    for section, key, raws in [("zenoh", "mode", ['"server"', "1"]), ("zenoh", "encoding", ['"xml"', '""']),
                               ("zenoh", "multicast_scouting", ['"yes"', "1"]), ("mission", "final_action", ['"crash"']),
                               ("scenario", "dim", ["4", '"3"']), ("scenario", "frame", ['"enu"']),
                               ("scenario", "carrier_mode", ['"fast"']), ("scenario", "planar_carrier", ['"true"', "0"]),
                               ("safety", "filter_carrier", ['"no"'])]:
        for raw in raws:
            add(section, key, raw)
    for raw in ['""', '"logs\\u0007"', '"' + "d" * 2000 + '"', "3"]:
        add("mission", "log_dir", raw)
    for raw in ['""', '"key\\nfile"', '"/nonexistent/key"', "1"]:
        add("mavlink", "signing_key_file", raw)
    for raw in ['""', '"/nonexistent/zenoh.json5"', '"a\\tb"']:
        add("zenoh", "config_file", raw)
    for raw in ['["lidar"]', '["Marker"]', '"marker"', '["a\\u0007"]', '["' + "f" * 100 + '"]', "[1]"]:
        add("mission", "feeds", raw)  # a measurement feed nothing registered, or not a name
    add("monte_carlo", "distance_m", "[60.0, 12.0]")
    add("monte_carlo", "height_m", '["0", 6.0]')
    add("monte_carlo", "distance_m", "[1.0, 2.0, 3.0]")
    # unknown fields and wrong shapes of whole sections
    add("law", "kc", "0.5", "law.kc")
    add("mission", "rate", "50.0", "mission.rate")
    cases.append(("law-not-a-table", DEMO.replace("[law]\n", "law = 3\n[law_x]\n", 1), "law"))
    cases.append(("unknown-section", DEMO + "\n[extra]\nx = 1\n", "extra"))
    # geometry across fields
    add("safety", "z_min_m", "-0.5", "safety.z_min_m")  # empty band: ceiling == floor
    add("safety", "z_min_m", "-3.0", "scenario.target")  # target (z -5) above the ceiling
    add("safety", "z_max_m", "-6.0", "mission.dock_offset_ned_m")  # floor above the dock (z -1.5) and target
    add("mission", "dock_offset_ned_m", "[0.0, 0.0, 1.5]")  # dock point underground
    add("scenario", "target", "[24.0, 18.0, 2.0]")  # target underground
    cases.append(("target-in-obstacle", DEMO + "\n[[scenario.obstacles]]\ncenter = [24.0, 18.0, -4.0]\nradius = 2.0\n",
                  "scenario.target"))
    cases.append(("start-in-obstacle", DEMO + "\n[[scenario.obstacles]]\ncenter = [0.5, 0.0, 0.0]\nradius = 1.0\n",
                  "scenario.carrier_start"))
    cases.append(("obstacle-radius-0", DEMO + "\n[[scenario.obstacles]]\ncenter = [10.0, 0.0, -2.0]\nradius = 0\n",
                  "scenario.obstacles"))
    cases.append(("obstacle-center-2d", DEMO + "\n[[scenario.obstacles]]\ncenter = [10.0, 0.0]\nradius = 1.0\n",
                  "scenario.obstacles"))
    add("mission", "carrier_timeout_s", "0.05", "carrier.rate_hz")  # 30 Hz carrier: < 2 states per timeout
    add("scenario", "target", "[4.0, 3.0, -1.0]", "scenario.eta")  # within b c at the start
    add("scenario", "target", "[24.0, 18.0, -12.0]", "scenario.target")  # too high to ever separate
    add("scenario", "dim", "2", "scenario.carrier_start")
    # the recovery and the carrier's course in it (validated whatever mission.final_action says)
    for key, raw, field in RECOVERY_MISTAKES:
        add(*key.split("."), raw, field)
    # what a flight must state itself (mission.config.required): on main an empty file flew to a
    # default target, and one without [safety] flew the unsaturated law (5.8e20 m/s, a traceback)
    cases.append(("empty-file", "", "scenario.target"))
    cases.append(("no-scenario", without("scenario"), "scenario.target"))
    cases.append(("no-safety", without("safety"), "safety.passenger_max_speed_m_s"))
    for key in ("target", "passenger_max_speed_m_s", "passenger_max_accel_m_s2", "carrier_max_speed_m_s",
                "carrier_max_accel_m_s2"):
        section = "scenario" if key == "target" else "safety"
        cases.append((f"no-{key}", without(section, key), f"{section}.{key}"))
    return cases


# (field, TOML value, the field the error names): bad recovery configurations
RECOVERY_MISTAKES = [
    ("recovery.glide_angle_deg", "0.0", "recovery.glide_angle_deg"),
    ("recovery.holdoff_distance_m", "0.5", "recovery.holdoff_distance_m"),  # inside the deck
    ("recovery.battery_reserve_pct", "101.0", "recovery.battery_reserve_pct"),
    ("carrier.recovery_speed_m_s", "50.0", "carrier.recovery_speed_m_s"),  # above carrier.max_speed_m_s
    ("carrier.recovery_heading_deg", "nan", "carrier.recovery_heading_deg"),
    ("carrier.recovery_course", "[[90.0, 1.0]]", "carrier.recovery_course[0]"),
    ("carrier.recovery_course", "[[90.0, 1.0, 0.0]]", "carrier.recovery_course[0]"),
    ("recovery.settle_carrier_speed_m_s", "2.5", "recovery.settle_carrier_speed_m_s"),  # above the carrier's top speed
    ("recovery.carrier_max_age_s", "0.05", "recovery.carrier_max_age_s"),  # under two carrier states (30 Hz)
]

# (field, TOML value, the field the error names): a recovery that cannot finish on configs/recovery.toml
# (mission.final_action = "return", the carrier's recovery course at 1.5 m/s)
RETURN_MISTAKES = [
    ("recovery.settle_carrier_speed_m_s", "1.8", "recovery.settle_carrier_speed_m_s"),  # faster than its course
    ("safety.passenger_max_speed_m_s", "1.5", "carrier.recovery_speed_m_s"),  # the passenger never catches it
]


def without(section: str, key: str | None = None) -> str:
    """demo.toml without its ``[section]`` table, or without ``key``'s line in it."""
    lines = DEMO.splitlines()
    start = lines.index(f"[{section}]")
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("[")), len(lines))
    if key is None:
        return "\n".join(lines[:start] + lines[end:]) + "\n"
    kept = [line for i, line in enumerate(lines) if not (start < i < end and re.match(rf"{re.escape(key)}\s*=", line))]
    assert len(kept) == len(lines) - 1, key
    return "\n".join(kept) + "\n"


CASES = _cases()


def test_there_are_at_least_200_mutations() -> None:
    assert len(CASES) >= 200, len(CASES)
    assert len({text for _, text, _ in CASES}) == len(CASES)  # all distinct


CLI_EVERY = 10  # one mutation in this many also runs `marsupial run` in process
IDS = [i[:60] for i, _, _ in CASES]


@pytest.fixture(scope="module")
def scratch(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One directory for the whole module: a mutation is written over the last one (tmp_path's
    own directory per case cost more than the check itself)."""
    return tmp_path_factory.mktemp("mutations")


@pytest.mark.parametrize("text, field", [(t, f) for _, t, f in CASES], ids=IDS)
def test_the_mutation_is_refused_at_load_naming_the_field(scratch: Path, text: str, field: str) -> None:
    path = scratch / "mutated.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:  # refused at load, before anything is opened (else: fail, never fly)
        check_config(load_config(path))  # what `marsupial run` checks before it opens anything
    assert str(info.value).startswith(field), (field, str(info.value)[:300])  # the CLI prints "error: {exc}"


@pytest.mark.parametrize("text, field", [(t, f) for _, t, f in CASES[::CLI_EVERY]], ids=IDS[::CLI_EVERY])
def test_run_refuses_the_mutation_with_exit_2_naming_the_field(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                               text: str, field: str) -> None:
    path = tmp_path / "mutated.toml"
    path.write_text(text)
    code = main(["run", str(path), "--log-dir", str(tmp_path / "log")])
    err = capsys.readouterr().err
    assert code == 2, err
    assert f"error: {field}" in err, (field, err[:300])
    assert "Traceback" not in err
    assert not (tmp_path / "log").exists()  # nothing was started


def test_broken_files_exit_2_naming_the_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    not_utf8 = tmp_path / "latin1.toml"
    not_utf8.write_bytes(DEMO.replace("# The demo", "# Th\xe9 demo").encode("latin-1"))
    not_toml = tmp_path / "broken.toml"
    not_toml.write_text(DEMO + "\n[law\n")
    for path in (not_utf8, not_toml, tmp_path, tmp_path / ("x" * 5000 + ".toml"), tmp_path / "missing.toml"):
        code = main(["run", str(path)])
        err = capsys.readouterr().err
        named = err.startswith("error: config = ") or "Invalid value for 'CONFIG'" in err  # click: a directory
        assert code == 2 and named and "Traceback" not in err, err[:300]


@pytest.mark.parametrize("text, field", [(t, f) for i, t, f in CASES if i.startswith(("mavlink.url=\"bogus\"",
                                                                                        "law.b=\"1.0\"",
                                                                                        "mission.rate_hz=0.001"))])
def test_the_real_process_exits_2(tmp_path: Path, text: str, field: str) -> None:
    path = tmp_path / "mutated.toml"
    path.write_text(text)
    out = subprocess.run([sys.executable, "-m", "mission.cli", "run", str(path)], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 2 and f"error: {field}" in out.stderr and "Traceback" not in out.stderr, out.stderr


@pytest.mark.parametrize("command", ["run", "carrier"])
def test_bad_recovery_configurations_stop_run_and_carrier_with_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                      command: str) -> None:
    """A glide angle of 0, a holdoff inside the deck, a reserve above 100 %, a carrier course it
    cannot drive: ``marsupial run`` and ``marsupial carrier`` refuse configs/recovery.toml so
    mutated before anything moves, naming the field (exit 2). In process; the real processes below."""
    for key, raw, field in RECOVERY_MISTAKES:
        path = tmp_path / "mutated.toml"
        path.write_text(mutated_text(RECOVERY, *key.split("."), raw))
        code = main([command, str(path), *(["--log-dir", str(tmp_path / "log")] if command == "run" else [])])
        err = capsys.readouterr().err
        assert code == 2 and f"error: {field}" in err and "Traceback" not in err, (key, raw, err[:300])
        assert not (tmp_path / "log").exists()


@pytest.mark.parametrize("command", ["run", "carrier"])
def test_a_recovery_that_cannot_finish_stops_run_and_carrier_with_exit_2(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str],
                                                                        command: str) -> None:
    """A holdoff waiting for a carrier faster than its top speed or than its recovery course, a
    carrier the passenger can never catch, an approach age limit under two carrier states: refused
    before anything moves, naming the field (exit 2). On main each was accepted and the recovery
    could only go around until it fell back."""
    for key, raw, field in RECOVERY_MISTAKES[-2:] + RETURN_MISTAKES:
        path = tmp_path / "mutated.toml"
        path.write_text(mutated_text(RECOVERY, *key.split("."), raw))
        code = main([command, str(path), *(["--log-dir", str(tmp_path / "log")] if command == "run" else [])])
        err = capsys.readouterr().err
        assert code == 2 and f"error: {field} = " in err and "Traceback" not in err, (key, raw, err[:300])
        assert not (tmp_path / "log").exists()


@pytest.mark.parametrize("command", ["run", "carrier"])
def test_the_real_processes_refuse_a_flat_glide_path(tmp_path: Path, command: str) -> None:
    path = tmp_path / "mutated.toml"
    path.write_text(mutated_text(RECOVERY, "recovery", "glide_angle_deg", "0.0"))
    out = subprocess.run([sys.executable, "-m", "mission.cli", command, str(path)], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 2 and "error: recovery.glide_angle_deg" in out.stderr, out.stderr
    assert "Traceback" not in out.stderr


@pytest.mark.parametrize("case", ["empty-file", "no-safety", "no-target", "no-carrier_max_accel_m_s2"])
def test_the_carrier_refuses_a_flight_without_its_target_or_limits(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                   case: str) -> None:
    """``marsupial carrier`` needs the target and the carrier's limits stated, like ``run``:
    exit 2 naming the field, nothing opened (the passenger's limits are not its business)."""
    text, field = next((t, f) for i, t, f in CASES if i == case)
    field = {"safety.passenger_max_speed_m_s": "safety.carrier_max_speed_m_s"}.get(field, field)
    path = tmp_path / "carrier.toml"
    path.write_text(text)
    code = main(["carrier", str(path), "--zenoh-listen", "tcp/127.0.0.1:9", "--summary", str(tmp_path / "c.json")])
    err = capsys.readouterr().err
    assert code == 2 and f"error: {field} = None: " in err and "Traceback" not in err, err[:300]
    assert not (tmp_path / "c.json").exists()


CYCLE = (CONFIGS / "cycle.toml").read_text()
CYCLE_TARGETS = "targets = [[24.0, 18.0, -5.0], [44.0, 4.0, -4.0]]"
# the second target ringed by twelve obstacles 10.5 m from it: nowhere b c + leg margin from it to start its leg
RING = "".join(f"\n[[scenario.obstacles]]\ncenter = [{44.0 + 10.5 * math.cos(a * math.pi / 6):.3f}, "
               f"{4.0 + 10.5 * math.sin(a * math.pi / 6):.3f}, 0.0]\nradius = 3.5\n" for a in range(12))
# (id, configs/cycle.toml so mutated, the field the error names): several targets that leave a leg no start
CYCLE_MISTAKES = [
    ("no-targets", CYCLE.replace(CYCLE_TARGETS, "targets = []"), "scenario.targets"),
    ("target-in-keep-out", CYCLE.replace(CYCLE_TARGETS, "targets = [[24.0, 18.0, -5.0], [28.0, 20.0, -4.0]]"),
     "scenario.targets[1]"),
    ("first-in-keep-out", CYCLE.replace(CYCLE_TARGETS, "targets = [[24.0, 18.0, -5.0], [44.0, 4.0, -4.0], [20.0, 12.0, -4.0]]"),
     "scenario.targets[2]"),
    ("start-in-keep-out", CYCLE.replace(CYCLE_TARGETS, "targets = [[24.0, 18.0, -5.0], [5.0, -3.0, -4.0]]"),
     "scenario.carrier_start"),
    ("second-too-high", CYCLE.replace(CYCLE_TARGETS, "targets = [[24.0, 18.0, -5.0], [44.0, 4.0, -9.0]]"),
     "scenario.targets[1]"),
    ("second-in-obstacle", CYCLE + "\n[[scenario.obstacles]]\ncenter = [44.0, 4.0, -4.0]\nradius = 1.0\n",
     "scenario.targets[1]"),
    ("no-drive-out", CYCLE + RING, "scenario.targets[1]"),
    # a bad entry is named as the file wrote it, scenario.targets[i] (on main: scenario.target, a field not in the file)
    ("first-underground", CYCLE.replace(CYCLE_TARGETS, "targets = [[24.0, 18.0, 5.0], [44.0, 4.0, -4.0]]"),
     "scenario.targets[0]"),
    ("first-too-high", CYCLE.replace(CYCLE_TARGETS, "targets = [[24.0, 18.0, -30.0], [44.0, 4.0, -4.0]]"),
     "scenario.targets[0]"),
    ("first-two-components", CYCLE.replace(CYCLE_TARGETS, "targets = [[24.0, 18.0], [44.0, 4.0, -4.0]]"),
     "scenario.targets[0]"),
    ("first-a-string", CYCLE.replace(CYCLE_TARGETS, 'targets = [[24.0, 18.0, "x"], [44.0, 4.0, -4.0]]'),
     "scenario.targets[0][2]"),
    ("second-nan", CYCLE.replace(CYCLE_TARGETS, "targets = [[24.0, 18.0, -5.0], [44.0, 4.0, nan]]"),
     "scenario.targets[1][2]"),
    ("first-in-obstacle", CYCLE + "\n[[scenario.obstacles]]\ncenter = [24.0, 18.0, -5.0]\nradius = 1.0\n",
     "scenario.targets[0]"),
    ("several-without-return", mutated_text(CYCLE, "mission", "final_action", '"hold"'), "mission.final_action"),
]


@pytest.mark.parametrize("text, field", [(t, f) for _, t, f in CYCLE_MISTAKES], ids=[i for i, _, _ in CYCLE_MISTAKES])
@pytest.mark.parametrize("command", ["run", "carrier", "simulate"])
def test_a_cycle_without_a_start_for_every_leg_exits_2_naming_the_field(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                        command: str, text: str, field: str) -> None:
    """An empty target list, a target inside another's keep-out (or the carrier's start inside
    one), a target it can never separate at, a leg with nowhere to start under the paper's
    Assumption 1 (mission/config/legs.py): ``run``, ``carrier`` and ``simulate`` refuse
    configs/cycle.toml so mutated before anything moves, naming the field (exit 2)."""
    path = tmp_path / "cycle.toml"
    path.write_text(text)
    extra = {"run": ["--log-dir", str(tmp_path / "log")], "carrier": ["--summary", str(tmp_path / "c.json")],
             "simulate": ["--json"]}[command]
    code = main([command, str(path), *extra])
    out, err = capsys.readouterr()
    assert code == 2 and f"error: {field} = " in err and "Traceback" not in err, err[:400]
    assert out == "" and not (tmp_path / "log").exists() and not (tmp_path / "c.json").exists()


def test_the_real_processes_refuse_a_leg_with_no_drive_out(tmp_path: Path) -> None:
    path = tmp_path / "cycle.toml"
    path.write_text(CYCLE + RING)
    for command in ("run", "carrier", "simulate"):
        out = subprocess.run([sys.executable, "-m", "mission.cli", command, str(path)], capture_output=True, text=True,
                             timeout=60)
        assert out.returncode == 2 and "error: scenario.targets[1] = [44.0, 4.0, -4.0]: no place to start its leg" \
            in out.stderr and "Traceback" not in out.stderr, (command, out.stderr)
