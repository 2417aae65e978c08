"""A team that is not one passenger per slot and per target (configs/team.toml mutated): two
passengers on one slot, slots that overlap, a target with no passenger, a duplicate system id, a
slot that does not exist, a passenger with no target, a fact the team declares stated again.
``marsupial run`` refuses each before anything is opened, exit 2, naming the field (in process;
the four a team most needs refused also through the real process); ``--passenger`` is checked the same way,
``demo`` refuses what a team's demo does not fly, and ``carrier`` and ``run`` refuse a single peer's
key on a team's bus, and a team's key directory (one key per robot) that is incomplete, shares a key,
is not given this robot's own private key, or is given for one passenger."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from mission.cli import main
from tests.conftest import CONFIGS

TEAM_PATH = CONFIGS / "team.toml"
TEAM = TEAM_PATH.read_text()


def changed(old: str, new: str) -> str:
    assert TEAM.count(old) == 1, old
    return TEAM.replace(old, new)


# (id, configs/team.toml so mutated, what the error starts with)
MISTAKES = [
    ("two-on-one-slot", changed('slot = "starboard"', 'slot = "port"'),
     "team.passengers[1].slot = 'port': also team.passengers[0]'s ('alpha'): one passenger per slot"),
    ("slots-overlap", changed("[0.0, 0.75, -0.5]", "[0.0, 0.3, -0.5]"),
     "team.slots[1].offset_ned_m = [0.0, 0.3, -0.5]: overlaps team.slots[0] ('port'): 1.05 m from it"),
    ("target-without-passenger", changed("targets = [0, 2]", "targets = [0]"),
     "scenario.targets[2] = 2: no passenger of team.passengers flies to it"),
    ("duplicate-system-id", changed("system_id = 2 ", "system_id = 1 "),
     "team.passengers[1].system_id = 1: also team.passengers[0]'s ('alpha')"),
    ("no-such-slot", changed('slot = "starboard"', 'slot = "stern"'),
     "team.passengers[1].slot = 'stern': no such slot in team.slots (port, starboard)"),
    ("no-target", changed("targets = [1]", "targets = []"), "team.passengers[1].targets = []: a passenger with no target"),
    ("target-out-of-range", changed("targets = [1]", "targets = [1, 3]"), "team.passengers[1].targets[1] = 3: no such target"),
    ("targets-out-of-order", changed("targets = [0, 2]", "targets = [2, 0]"),
     "team.passengers[0].targets[1] = 0: after 2: a passenger's targets go in the mission's order"),
    ("target-of-two", changed("targets = [1]", "targets = [1, 2]"),
     "team.passengers[1].targets[1] = 2: also team.passengers[0]'s ('alpha'): one passenger per target"),
    ("duplicate-name", changed('name = "bravo"', 'name = "alpha"'), "team.passengers[1].name = 'alpha'"),
    ("duplicate-slot-name", changed('name = "starboard"', 'name = "port"'), "team.slots[1].name = 'port'"),
    ("dock-offset-stated-too", changed("[mission]\n", "[mission]\ndock_offset_ned_m = [0.0, 0.0, -0.5]\n"),
     "mission.dock_offset_ned_m = [0.0, 0.0, -0.5]: with a [team] each passenger's comes from team.slots[].offset_ned_m"),
    ("system-id-stated-too", changed("[mavlink]\n", "[mavlink]\ntarget_system = 1\n"),
     "mavlink.target_system = 1: with a [team] each passenger's comes from team.passengers[].system_id"),
    ("slot-underground", changed("[0.0, 0.75, -0.5]", "[0.0, 0.75, 0.5]"), "team.slots[1].offset_ned_m = [0.0, 0.75, 0.5]"),
    ("slot-two-components", changed("[0.0, 0.75, -0.5]", "[0.75, -0.5]"), "team.slots[1].offset_ned_m = [0.75, -0.5]"),
    ("slot-a-string", changed("[0.0, 0.75, -0.5]", '"starboard"'), "team.slots[1].offset_ned_m = 'starboard'"),
    ("system-id-256", changed("system_id = 2 ", "system_id = 256 "), "team.passengers[1].system_id = 256"),
    ("system-id-a-fraction", changed("system_id = 2 ", "system_id = 2.0 "), "team.passengers[1].system_id = 2.0"),
    ("target-a-fraction", changed("targets = [1]", "targets = [1.0]"), "team.passengers[1].targets[0] = 1.0"),
    ("slots-no-passenger", TEAM[:TEAM.index("[team]")] + '[team]\n\n[[team.slots]]\nname = "port"\n'
     "offset_ned_m = [0.0, -0.75, -0.5]\n", "team.passengers = []: a [team] needs at least one passenger"),
    ("unknown-field", changed("[team]\n", "[team]\nslot_spacing_m = 1.0\n"), "team.slot_spacing_m"),
    ("system-id-of-the-carrier",  # a PX4 rover carrier with bravo's system id
     changed("[carrier]\n", '[carrier]\nbackend = "mavlink"\n') + "\n[carrier.mavlink]\ntarget_system = 2\n",
     "team.passengers[1].system_id = 2: also the carrier's"),
]


@pytest.mark.parametrize("text, error", [(t, e) for _, t, e in MISTAKES], ids=[i for i, _, _ in MISTAKES])
def test_run_refuses_the_team_with_exit_2_naming_the_field(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                          text: str, error: str) -> None:
    path = tmp_path / "team.toml"
    path.write_text(text)
    code = main(["run", str(path), "--passenger", "alpha", "--log-dir", str(tmp_path / "log")])
    out, err = capsys.readouterr()
    assert code == 2 and f"error: {error}" in err and "Traceback" not in err, err[:400]
    assert out == "" and not (tmp_path / "log").exists()  # nothing said about flying, nothing started


@pytest.mark.parametrize("case", ["two-on-one-slot", "slots-overlap", "target-without-passenger", "duplicate-system-id"])
def test_the_real_process_refuses_issue_36s_bad_teams(tmp_path: Path, case: str) -> None:
    text, error = next((t, e) for i, t, e in MISTAKES if i == case)
    path = tmp_path / "team.toml"
    path.write_text(text)
    out = subprocess.run([sys.executable, "-m", "mission.cli", "run", str(path), "--passenger", "bravo"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and f"error: {error}" in out.stderr and "Traceback" not in out.stderr, out.stderr


@pytest.mark.parametrize("args, error", [
    ([str(TEAM_PATH), "--passenger", "charlie"], "--passenger = 'charlie': no such passenger in team.passengers (alpha, bravo)"),
    ([str(TEAM_PATH)], "--passenger = None: the file's [team] has 2 passengers: say which this process flies (alpha, bravo)"),
    ([str(CONFIGS / "recovery.toml"), "--passenger", "alpha"], "--passenger = 'alpha': the file has no [team] section"),
])
def test_run_refuses_a_passenger_it_cannot_choose(tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str],
                                                  error: str) -> None:
    code = main(["run", *args, "--log-dir", str(tmp_path / "log")])
    out, err = capsys.readouterr()
    assert code == 2 and f"error: {error}" in err and out == "" and not (tmp_path / "log").exists(), err[:400]


def test_run_help_says_what_passenger_does(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "--passenger NAME" in text and "fly passenger NAME of team.passengers" in text
    assert "Refused (exit 2) for a file without a [team]" in text


def test_the_demo_refuses_what_a_team_does_not_fly(tmp_path: Path) -> None:
    out = subprocess.run([sys.executable, "-m", "mission.cli", "demo", "--config", str(TEAM_PATH), "--pairs", "2",
                          "--log-root", str(tmp_path / "demo")], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "error: --pairs = 2: a team's demo flies one team" in out.stderr, out.stderr
    assert "Traceback" not in out.stderr
    assert not (tmp_path / "demo").exists()  # refused before anything started


@pytest.mark.parametrize("command", ["carrier", "run"])
def test_a_single_peer_key_is_refused_for_a_team_of_several(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                            command: str) -> None:
    from mission.config.keys import write_key_pair

    write_key_pair(tmp_path / "own.key", tmp_path / "own.pub")
    write_key_pair(tmp_path / "peer.key", tmp_path / "peer.pub")
    keys = ["--zenoh-private-key", str(tmp_path / "own.key"), "--zenoh-peer-key", str(tmp_path / "peer.pub")]
    extra = ["--summary", str(tmp_path / "c.json")] if command == "carrier" else [
        "--passenger", "alpha", "--log-dir", str(tmp_path / "log")]
    code = main([command, str(TEAM_PATH), "--zenoh-listen", "tcp/127.0.0.1:9", *keys, *extra])
    err = capsys.readouterr().err
    assert code == 2 and "error: zenoh.peer_public_key_file" in err and "one peer key for a team of 2" in err, err
    assert not (tmp_path / "c.json").exists() and not (tmp_path / "log").exists()


def _team_keys(folder: Path, robots: tuple[str, ...] = ("carrier", "alpha", "bravo")) -> Path:
    """A team's key directory: a key pair per robot, ``<robot>.key`` beside ``<robot>.pub``."""
    from mission.config.keys import write_key_pair

    folder.mkdir()
    for robot in robots:
        write_key_pair(folder / f"{robot}.key", folder / f"{robot}.pub")
    return folder


def _refused(command: str, tmp_path: Path, config: Path, keys: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """``command`` on ``config`` with ``keys``: exit 2 before anything is written; its stderr."""
    extra = ["--summary", str(tmp_path / "c.json")] if command == "carrier" else [
        "--log-dir", str(tmp_path / "log"), *(["--passenger", "alpha"] if "[team]" in config.read_text() else [])]
    code = main([command, str(config), "--zenoh-listen", "tcp/127.0.0.1:9", *keys, *extra])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err, err
    assert not (tmp_path / "c.json").exists() and not (tmp_path / "log").exists()
    return err


@pytest.mark.parametrize("command", ["carrier", "run"])
def test_a_teams_key_directory_needs_this_robots_own_private_key(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                 command: str) -> None:
    keys = _team_keys(tmp_path / "keys")
    err = _refused(command, tmp_path, TEAM_PATH, ["--zenoh-public-keys", str(keys)], capsys)
    assert "error: zenoh.private_key_file" in err and "signs with its own private key" in err, err


@pytest.mark.parametrize("command, wrong", [("carrier", "alpha"), ("run", "bravo"), ("run", "carrier")])
def test_a_private_key_that_is_not_this_robots_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                          command: str, wrong: str) -> None:
    """The carrier given a passenger's key, or passenger alpha given bravo's or the carrier's: it
    would sign as another robot. Refused, naming the private key."""
    keys = _team_keys(tmp_path / "keys")
    err = _refused(command, tmp_path, TEAM_PATH, ["--zenoh-public-keys", str(keys), "--zenoh-private-key",
                                                  str(keys / f"{wrong}.key")], capsys)
    me = "the carrier" if command == "carrier" else "passenger alpha"
    assert "error: zenoh.private_key_file" in err and f"not {me}'s key" in err, err


@pytest.mark.parametrize("command", ["carrier", "run"])
def test_a_key_directory_missing_a_robot_or_sharing_a_key_is_refused(tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str],
                                                                     command: str) -> None:
    me = "carrier" if command == "carrier" else "alpha"
    keys = _team_keys(tmp_path / "keys", ("carrier", "alpha"))  # no bravo.pub
    own = ["--zenoh-public-keys", str(keys), "--zenoh-private-key", str(keys / f"{me}.key")]
    err = _refused(command, tmp_path, TEAM_PATH, own, capsys)
    assert "error: zenoh.public_keys_dir" in err and "bravo.pub" in err and "cannot read the key file" in err, err
    (keys / "bravo.pub").write_bytes((keys / "alpha.pub").read_bytes())  # bravo on alpha's key: could sign as alpha
    err = _refused(command, tmp_path, TEAM_PATH, own, capsys)
    assert "error: zenoh.public_keys_dir" in err and "alpha.pub and bravo.pub hold the same key" in err, err


@pytest.mark.parametrize("command", ["carrier", "run"])
def test_a_key_directory_is_a_teams_and_not_beside_a_peer_key(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                              command: str) -> None:
    keys = _team_keys(tmp_path / "keys")
    me = "carrier" if command == "carrier" else "passenger"
    pair = ["--zenoh-public-keys", str(keys), "--zenoh-private-key", str(keys / ("carrier.key" if me == "carrier"
                                                                                 else "alpha.key"))]
    err = _refused(command, tmp_path, CONFIGS / "recovery.toml", pair, capsys)  # one passenger
    assert "error: zenoh.public_keys_dir" in err and "a team's key directory" in err, err
    both = [*pair, "--zenoh-peer-key", str(keys / "bravo.pub")]
    err = _refused(command, tmp_path, TEAM_PATH, both, capsys)
    assert "error: zenoh.peer_public_key_file" in err and "zenoh.public_keys_dir" in err, err


def _hovering(apart_m: float) -> str:
    """configs/team.toml riding hovering 1.5 m above the carrier, its two slots ``apart_m`` apart
    (its queue 1 m higher: wider slots' queue points come nearer the other's approach)."""
    text = changed('ride = "deck"\n', 'ride = "hover"\n').replace("queue_height_m = 3.8", "queue_height_m = 4.8")
    half = apart_m / 2.0
    return (text.replace("[0.0, -0.75, -0.5]", f"[0.0, {-half!r}, -1.5]")
            .replace("[0.0, 0.75, -0.5]", f"[0.0, {half!r}, -1.5]"))


@pytest.mark.parametrize("command", ["carrier", "run"])
def test_a_team_riding_hovering_on_slots_its_riders_could_touch_on_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str) -> None:
    """Riding hovering, each passenger hovers where its estimate puts it: the deck's slots, 1.5 m
    apart, leave two riders' 0.8 m spans 0.35 m of margin each, under safety.margin_m (0.5 m). The
    deck ride's rule (span + 2 contact radii, 1.1 m) is not enough."""
    path = tmp_path / "team.toml"
    path.write_text(_hovering(1.5))
    err = _refused(command, tmp_path, path, [], capsys)
    assert ("error: team.slots[1].offset_ned_m = [0.0, 0.75, -1.5]: 1.50 m from team.slots[0] ('port') horizontally: "
            "a team riding hovering needs team.passenger_span_m + 2 safety.margin_m = 1.8 m") in err, err


def test_a_team_riding_hovering_far_enough_apart_is_not_refused() -> None:
    import tomllib

    from mission.config.passenger import check_team_flight
    from mission.config.schema import from_dict
    from mission.errors import ConfigError

    check_team_flight(from_dict(tomllib.loads(_hovering(1.8))))
    check_team_flight(from_dict(tomllib.loads(TEAM)))  # the deck ride: the contact radius' rule, checked at load
    with pytest.raises(ConfigError, match=r"team.slots\[1\].offset_ned_m"):
        check_team_flight(from_dict(tomllib.loads(_hovering(1.79))))
