"""``marsupial demo``: the whole system on embedded defaults, no hardware, no external router.

For each marsupial pair it starts three processes that talk over real sockets: the mock
vehicle (MAVLink over UDP), the carrier simulator (Zenoh) and the mission controller
(``marsupial run``). The pairs share one Zenoh network: the demo hosts a Zenoh router session on
a free loopback port and every process connects to it, each pair in its own key namespace
``marsupial/<pair>/...`` with its own MAVLink port. It shows the live phase of each mission,
then prints a summary table, writes a plot per pair and exits 0 when P1-P3 held for every pair
(and, with ``mission.final_action = "return"``, the passenger docked on its carrier again).
The robots sign their bus samples, one throwaway Ed25519 key per robot (``zenoh.private_key_file``,
``zenoh.peer_public_key_file``, :mod:`mission.bus.signing`; a ROS-2-shaped robot and its carrier
share a throwaway key), made at the start and deleted at the end.
"""
from __future__ import annotations

import json
import os
import secrets
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path

import click

from mission.bus.auth import unsigned_warning
from mission.bus.bridge import open_session
from mission.bus.session import close_session
from mission.config.passenger import sole_passenger
from mission.config.schema import CarrierRos2Section, Config, ZenohSection, load_config
from mission.errors import MarsupialError
from mission.flightdata.writer import DEFAULT_LIVE, LiveAddress, is_loopback, parse_live
from mission.lifetime import supervise_children
from sim.net import child_stderr, free_port, stop_process
from sim.progress import watch_missions
from sim.robots.truth import demo_truth
from sim.team_demo import child_command as _python_cli, run_team_demo, team_lines
from sim.vehicle.options import VehicleOptions

DEFAULT_CONFIG = Path(__file__).resolve().parents[1] / "configs" / "demo.toml"
# The nominal path of a mission; HOLD and LAND are alternatives of the same step.
@dataclass
class PairRun:
    """The processes and state of one pair in the demo."""

    name: str
    log_dir: Path
    procs: dict[str, subprocess.Popen] = field(default_factory=dict)
    phase: str = "starting"
    lines: list[str] = field(default_factory=list)

    def summary(self) -> dict:
        path = self.log_dir / "summary.json"
        return json.loads(path.read_text()) if path.exists() else {}


def start_carrier_robot(kind: str, name: str, zenoh_ep: str, speed: float, start: str, stack: ExitStack,
                        logs: Path | None, lockstep: bool = False, bus_key: Path | None = None,
                        cfg: Config | None = None) -> tuple[list[str], subprocess.Popen | None]:
    """The robot under a ``kind`` carrier ("sim": built in, none to start; "mavlink": a mock PX4
    rover, sysid 2; "ros2": a ROS-2-shaped robot on rmw_zenoh keys in namespace ``name``, taking
    the command type and sending the attachment form of ``cfg.carrier.ros2``, a Zenoh client of
    the demo's router when ``cfg.zenoh.mode`` is "client" (as an rmw_zenoh node of its host's
    ``rmw_zenohd``), and only commands signed with ``bus_key`` if given; with ``lockstep`` both
    step on the carrier's clock) and the carrier controller's arguments for it. ``logs``: the
    robot's log goes to ``carrier_robot.log`` there (None: to this process's stderr)."""
    if kind == "mavlink":
        port = free_port(socket.SOCK_DGRAM)
        robot = subprocess.Popen(_python_cli("mock-vehicle", "--frame", "rover", "--sysid", "2", "--mavlink",
                                             "udpin:127.0.0.1:0", "--target", f"udpout:127.0.0.1:{port}", "--speed",
                                             str(speed), "--start-ned", start, *(["--lockstep"] if lockstep else [])),
                                 stderr=child_stderr(stack, logs, "carrier_robot"))
        stack.callback(stop_process, robot)
        return ["--backend", "mavlink", "--mavlink", f"udpin:127.0.0.1:{port}", "--target-system", "2",
                "--kinematics", "ackermann"], robot
    if kind == "ros2":
        signed = ["--signing-key", str(bus_key), "--pair", name] if bus_key is not None else []
        ros2 = cfg.carrier.ros2 if cfg is not None else CarrierRos2Section()
        client = ["--zenoh-mode", "client"] if cfg is not None and cfg.zenoh.mode == "client" else []
        robot = subprocess.Popen(_python_cli("ros2-robot", "--key-form", "rmw_zenoh", "--namespace", name, *client,
                                             "--cmd-vel-type", ros2.cmd_vel_type, "--rmw-attachment", ros2.rmw_attachment,
                                             "--zenoh-connect", zenoh_ep, "--speed", str(speed), *signed,
                                             *(["--lockstep"] if lockstep else [])),
                                 stderr=child_stderr(stack, logs, "carrier_robot"))
        stack.callback(stop_process, robot)
        return ["--backend", "ros2", "--key-form", "rmw_zenoh", "--ros2-namespace", name, "--kinematics",
                "diff_drive", "--offset-ned", start], robot  # its odometry starts at zero where it stands
    return ["--backend", "sim"], None


def throwaway_key(stack: ExitStack, name: str = "bus.key") -> Path:
    """A fresh random 32-byte signing key in a private temporary file ``name`` (mode 0600), removed
    when ``stack`` closes. The bus key: each pair signs with its own key derived from it
    (``mission.bus.signing``); the MAVLink key (``mavlink.key``): every pair's vehicle and mission."""
    folder = Path(tempfile.mkdtemp(prefix="marsupial-demo-"))
    stack.callback(shutil.rmtree, folder, True)
    path = folder / name
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(secrets.token_hex(32) + "\n")
    return path


def robot_keys(folder: Path, pair: str) -> dict[str, tuple[Path, Path]]:
    """A throwaway Ed25519 key pair for each robot of ``pair`` in the private ``folder``:
    ``{"carrier": (private, public), "passenger": (private, public)}`` (private keys mode 0600)."""
    from mission.config.keys import write_key_pair

    made = {}
    for robot in ("carrier", "passenger"):
        made[robot] = (folder / f"{pair}-{robot}.key", folder / f"{pair}-{robot}.pub")
        write_key_pair(*made[robot])
    return made


def start_pair(config: str, name: str, zenoh_ep: str, speed: float, log_root: Path, stack: ExitStack,
               quiet: bool, carrier_kind: str = "sim", lockstep: bool = False, live: LiveAddress | None = None,
               bus_key: Path | None = None, mav_key: Path | None = None, seed: int = 0,
               estimate_error: float = VehicleOptions.estimate_error) -> PairRun:
    """Start the carrier (and its robot), the mock vehicle and the mission of one pair; register their cleanup.
    The vehicle learns the carrier's motion from the pair's Zenoh state (``--deck``): it stands on
    the carrier's deck until it takes off, and lands or crashes on it as it comes back. With
    ``mission.ride = "deck"`` the deck is the dock point (``--deck-height``) and the vehicle starts on it.
    With ``bus_key`` (a key file) the pair signs its bus samples, each robot with a throwaway key of
    its own made beside it (:func:`robot_keys`; a ROS-2-shaped robot and its carrier also with
    ``bus_key``); with
    ``mav_key`` the vehicle and the mission sign their MAVLink link (``--signing-key``).

    ``lockstep``: the three step on the mock vehicle's simulated time, the carrier's robot on the
    carrier's (``speed`` is then the pace after a participant is lost), and the mission and the
    carrier count their flight data's log times from one epoch (``--log-epoch-ns``); else wall
    clocks scaled by ``speed``. ``live``: the mission serves its flight to Foxglove there (``run --live``).
    ``estimate_error``: the vehicle's estimate errs this many times as PX4 SITL's does (0: exact;
    ``mock-vehicle --estimate-error``), drawn from ``seed`` (``mock-vehicle --seed``). ``quiet``: each
    child's log (its stderr) goes to ``<child>.log`` in the pair's flight folder, else to ours."""
    cfg = load_config(config)
    pair = PairRun(name=name, log_dir=log_root / name)
    mav_port = free_port(socket.SOCK_DGRAM)
    logs = pair.log_dir if quiet else None  # quiet: each child's log goes to <name>.log beside its flight
    mode = ["--lockstep"] if lockstep else []
    # in lockstep the mission and the carrier log on one simulated clock: one epoch lines their files up
    epoch = ["--log-epoch-ns", str(time.time_ns())] if lockstep else []
    start = ",".join(str(v) for v in cfg.scenario.carrier_start)
    signed, carrier_signed = [], []
    if bus_key is not None:
        keys_of = robot_keys(bus_key.parent, name)
        signed = ["--zenoh-private-key", str(keys_of["passenger"][0]), "--zenoh-peer-key", str(keys_of["carrier"][1])]
        carrier_signed = ["--zenoh-private-key", str(keys_of["carrier"][0]), "--zenoh-peer-key",
                          str(keys_of["passenger"][1]), *(["--zenoh-signing-key", str(bus_key)] if carrier_kind == "ros2" else [])]
    mav_signed = ["--signing-key", str(mav_key)] if mav_key is not None else []
    # the passenger's camera node signs its frames with the passenger's own key, as run checks them
    camera_signed = ["--zenoh-private-key", str(keys_of["passenger"][0])] if bus_key is not None and "--camera" in world_args(
        cfg, config) else []
    backend_args, robot = start_carrier_robot(carrier_kind, name, zenoh_ep, speed, start, stack, logs, lockstep, bus_key,
                                              cfg)
    carrier = subprocess.Popen(_python_cli("carrier", config, "--speed", str(speed), "--pair", name,
                                           "--zenoh-connect", zenoh_ep, "--summary", str(pair.log_dir / "carrier.json"),
                                           "--mcap", str(pair.log_dir / "carrier.mcap"), *backend_args, *carrier_signed,
                                           *mode, *epoch),
                               stderr=child_stderr(stack, logs, "carrier"))
    stack.callback(stop_process, carrier)
    # riding on the deck (mission.ride = "deck"): the deck is the dock point, the vehicle stands on it
    on_deck = cfg.mission.ride == "deck"
    deck_height = -cfg.mission.dock_offset_ned_m[2] if on_deck else 0.0
    vehicle_start = ",".join(str(c + (o if on_deck else 0.0)) for c, o in
                             zip(cfg.scenario.carrier_start, cfg.mission.dock_offset_ned_m))
    vehicle = subprocess.Popen(_python_cli("mock-vehicle", "--mavlink", "udpin:127.0.0.1:0", "--target",
                                           f"udpout:127.0.0.1:{mav_port}", "--speed", str(speed), "--start-ned",
                                           vehicle_start, "--deck", name, "--deck-height", str(deck_height),
                                           "--zenoh-connect", zenoh_ep, "--summary", str(pair.log_dir / "vehicle.json"),
                                           "--estimate-error", str(estimate_error), "--seed", str(seed), *world_args(cfg, config),
                                           *camera_signed, *mav_signed, *mode),
                               stderr=child_stderr(stack, logs, "vehicle"))
    stack.callback(stop_process, vehicle)
    live_args = [] if live is None else ["--live", f"{live.host}:{live.port}"]
    mission = subprocess.Popen(_python_cli("run", config, "--mavlink", f"udpin:127.0.0.1:{mav_port}", "--zenoh-connect",
                                           zenoh_ep, "--pair", name, "--speed", str(speed), "--log-dir", str(pair.log_dir),
                                           *signed, *mav_signed, *mode, *epoch, *live_args),
                               stdout=subprocess.PIPE, stderr=child_stderr(stack, logs, "mission"), text=True)
    stack.callback(stop_process, mission, 30.0)
    pair.procs = {"carrier": carrier, "vehicle": vehicle, "mission": mission}
    if robot is not None:
        pair.procs["carrier_robot"] = robot
    return pair


def world_args(cfg: Config, config: str) -> list[str]:
    """The mock vehicle's arguments for the world's errors and sensors of ``cfg`` (file ``config``):
    the passenger's GNSS bias (``--world``), the deck on the carrier's truth when the carrier flies
    its GNSS errors (``--deck-truth``), the downward camera's frames for the feed ``marker``
    (``--camera``), the downward rangefinder's DISTANCE_SENSOR for the feed ``rangefinder`` (the
    ``--world`` file's ``mission.feeds`` names it)."""
    w = cfg.world
    camera, ranged = "marker" in cfg.mission.feeds, "rangefinder" in cfg.mission.feeds
    return [*(["--world", config] if camera or ranged or w.passenger_gnss.bias_sigma_m > 0 else []),
            *(["--deck-truth"] if w.carrier_gnss.enabled else []), *(["--camera"] if camera else [])]


def live_addresses(live: LiveAddress | None, pairs: int) -> list[LiveAddress | None]:
    """Each pair's live view: pair i on ``live``'s port + i (port 0: each any free port)."""
    if live is None:
        return [None] * pairs
    return [LiveAddress(live.host, live.port + i if live.port else 0) for i in range(pairs)]


def run_demo(config: str, speed: float, pairs: int, log_root: Path, plot_path: str | None, timeout_s: float,
             quiet: bool = True, progress: bool = True, carrier: str = "sim",
             lockstep: bool = True, live: LiveAddress | None = None, signed: bool = True, seed: int = 0,
             estimate_error: float = VehicleOptions.estimate_error) -> tuple[int, list[dict]]:
    """Run ``pairs`` marsupial pairs, in lockstep on each mock vehicle's simulated time or at
    ``speed``; return the exit code and each pair's summary. ``live``: pair i serves its flight
    to Foxglove on ``live``'s port + i (topics ``/pair<i>/...``). ``signed``: the pairs sign their
    bus samples, and each vehicle and mission their MAVLink link, with throwaway keys
    (:func:`throwaway_key`), deleted at the end. ``seed``: pair i's vehicle's is ``seed + i``; ``estimate_error``: its estimate's errors as a multiple of PX4 SITL's (0: exact)."""
    from mission.cli.run import plot as plot_command

    if len(load_config(config).team.passengers) > 1:  # a team: one carrier, a vehicle and a mission each
        return run_team_demo(config, speed, log_root, timeout_s, quiet=quiet, progress=progress, signed=signed, seed=seed,
                             estimate_error=estimate_error, pairs=pairs, carrier=carrier, live=live, lockstep=lockstep,
                             plot_path=plot_path)
    sole_passenger(load_config(config), "flown by demo", team_of_one=False)  # its processes read the file themselves
    supervise_children()  # a demo killed outright takes its processes with it
    log_root.mkdir(parents=True, exist_ok=True)
    zenoh_port = free_port(socket.SOCK_STREAM)
    zenoh_ep = f"tcp/127.0.0.1:{zenoh_port}"
    with ExitStack() as stack:
        bus_key = throwaway_key(stack) if signed else None
        mav_key = throwaway_key(stack, "mavlink.key") if signed else None
        if not signed:
            print(unsigned_warning(ZenohSection()), file=sys.stderr)
        router = open_session(ZenohSection(mode="router", listen=[zenoh_ep]))
        stack.callback(close_session, router)
        runs = [start_pair(config, f"pair{i}", zenoh_ep, speed, log_root, stack, quiet, carrier, lockstep, address, bus_key,
                           mav_key, seed + i, estimate_error)
                for i, address in enumerate(live_addresses(live, pairs))]
        for r in watch_missions(runs, timeout_s, progress, stack):
            r.join(timeout=5.0)
    summaries = []
    for p in runs:
        s = p.summary()
        s.update(pair=p.name, mission_exit_code=p.procs["mission"].returncode)
        carrier_summary = p.log_dir / "carrier.json"
        if carrier_summary.exists():  # the carrier's own account (written when it stops)
            c = json.loads(carrier_summary.read_text())
            s["carrier_stop_target_distance_m"] = c.get("stopped_target_distance_m")
            s["carrier_braking_distance_m"] = c.get("braking_distance_m")
            s["carrier_lockstep"] = c.get("lockstep")
        if lockstep:
            s["not_lockstep"] = not_lockstep(s)
        s.update(deck_truth(p.log_dir / "vehicle.json"))
        truth = demo_truth(load_config(config), p.log_dir)
        if truth:  # the figures against the world's truth, per leg; kept beside the mission's summary
            (p.log_dir / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")
        for leg, row in zip(s.get("legs") or [s], truth.get("truth_legs") or []):
            leg.update(row)
        s.update(recovery_cells(s))
        summaries.append(s)
        if plot_path and (p.log_dir / "record.csv").exists():
            out = plot_path if pairs == 1 else str(Path(plot_path).with_stem(f"{Path(plot_path).stem}-{p.name}"))
            try:
                plot_command.callback(str(p.log_dir), out)  # type: ignore[misc]
                s["plot"] = out
                recovery = Path(out).with_stem(f"{Path(out).stem}-recovery")  # a flight that came home
                if recovery.exists():
                    s["recovery_plot"] = str(recovery)
            except MarsupialError as exc:
                s["plot_error"] = str(exc)
    return exit_code(summaries), summaries


def exit_code(summaries: list[dict]) -> int:
    """0 when every pair held P1-P3, its mission exited 0, a passenger that returned docked again,
    no deck crash was recorded by the world (whatever the mission believed) and a lockstep run
    stayed in step (``not_lockstep`` empty); else 1."""
    ok = all(s.get("p1") and s.get("p2") and s.get("p3") and s.get("mission_exit_code") == 0
             and s.get("docked_again", True) and not s.get("deck_crash") and not s.get("not_lockstep") for s in summaries)
    return 0 if ok else 1


def not_lockstep(s: dict) -> str | None:
    """Why a lockstep pair's run did not stay in step (its mission's and its carrier's clock
    counters, ``lockstep`` and ``carrier_lockstep``), or None: a run that went on without a
    participant for a while proves nothing about the lockstep flight."""
    lock, carrier = s.get("lockstep") or {}, s.get("carrier_lockstep") or {}
    why = [*(["the mission never stepped in lockstep"] if not lock.get("barriers") else []),
           *([f"the mission's clock fell back to the wall clock ({lock['fallback']})"] if lock.get("fallback") else []),
           *([f"the carrier was dropped {lock['downstream_dropped']} time(s) (rejoined "
              f"{lock.get('downstream_rejoined', 0)})"] if lock.get("downstream_dropped") else []),
           *([f"the carrier's clock fell back to the wall clock ({carrier['fallback']})"] if carrier.get("fallback") else []),
           *([f"the carrier's robot was dropped {carrier['downstream_dropped']} time(s)"]
             if carrier.get("downstream_dropped") else [])]
    return "; ".join(why) or None


def deck_truth(path: Path) -> dict:
    """The world's truth beside the mission's belief, from the mock vehicle's ``--summary``: where
    it last touched the deck, from the deck's true centre [m] (``deck_touchdown_m``), and a crash
    (``deck_crash``: why). A crash overrides the mission's account: the recovery's outcome is
    "crash", the passenger did not dock again."""
    if not path.exists():
        return {}
    deck = json.loads(path.read_text()).get("deck") or {}
    touchdowns = list(deck.get("touchdowns") or [])
    if touchdowns and touchdowns[0].get("vertical_speed_m_s") == 0.0 and touchdowns[0].get("horizontal_speed_m_s") == 0.0:
        touchdowns = touchdowns[1:]  # standing on it when the deck was first known, not a landing
    out: dict = {"deck_touchdown_m": touchdowns[-1]["horizontal_error_m"] if touchdowns else None,
                 "deck_crash": deck.get("crash")}
    if out["deck_crash"]:
        out.update(recovery_outcome=f"crash: {out['deck_crash']}", docked_again=False,
                   deck_crash_t_s=next(t["t_s"] for t in reversed(touchdowns) if t.get("crash")))
    return out


def _crashed_leg(s: dict, legs: list[dict]) -> int | None:
    """The index of the leg whose contact came nearest the deck crash (simulated time), or None."""
    at = s.get("deck_crash_t_s")
    times = [(abs((leg.get("contact") or {}).get("time_s", float("inf")) - at), i) for i, leg in enumerate(legs)] \
        if at is not None else []
    return min(times)[1] if times else None


# The recovery's rows (mission.final_action = "return"), shown when a pair tried one.
RECOVERY_ROWS = [
    ("recovery outcome", "recovery_outcome"),
    ("approaches flown to the dock (attempts)", "contact_attempts"),
    ("horizontal error at contact [m]", "contact_horizontal_error_m"),
    ("horizontal relative speed at contact [m/s]", "contact_horizontal_relative_speed_m_s"),
    ("vertical relative speed at contact [m/s]", "contact_vertical_relative_speed_m_s"),
    ("carrier speed on the approach [m/s]", "carrier_speed_on_approach"),
    ("max command jump at a phase switch [m/s]", "max_phase_switch_jump_m_s"),
    ("deck touched outside contact [ticks]", "deck_violations"),
    ("truth: last touchdown from the deck's centre [m]", "deck_touchdown_m"),
    ("truth: contact error, horizontal [m]", "true_contact_horizontal_m"),
    ("truth: riding offset, horizontal median [m]", "true_riding_horizontal_median_m"),
    ("truth: riding offset, horizontal max [m]", "true_riding_horizontal_max_m"),
]
RECOVERY_KEYS = {key for _, key in RECOVERY_ROWS}
DECK_KEYS = {"takeoff_command_jump_m_s", "takeoff_max_command_step_m_s", "takeoff_clear_s"}  # shown when a pair rode the deck


def recovery_cells(s: dict) -> dict:
    """The recovery's table cells from a summary: the contact's figures, the carrier's speed range
    on the approach as text (none without a recovery)."""
    if "recovery_outcome" not in s:
        return {}
    contact = s.get("contact") or {}
    speeds = s.get("carrier_speed_on_approach_m_s")
    return {f"contact_{k}": contact.get(k) for k in ("attempts", "horizontal_error_m", "horizontal_relative_speed_m_s",
                                                      "vertical_relative_speed_m_s")} | {
        "carrier_speed_on_approach": None if not speeds else f"{speeds[0]:.2f}-{speeds[1]:.2f}"}


ROWS = [
    ("separation time [s]", "separation_time_s"),
    ("carrier-target distance at separation [m]", "carrier_target_distance_at_separation_m"),
    ("relative command jump at separation [m/s]", "relative_input_jump_m_s"),
    ("relative command jump at a switch of the take-off from the deck [m/s]", "takeoff_command_jump_m_s"),
    ("largest relative command step, take-off from the deck [m/s]", "takeoff_max_command_step_m_s"),
    ("from separation to clear of the deck [s]", "takeoff_clear_s"),
    ("closest carrier-target approach [m]", "min_carrier_target_distance_m"),
    ("carrier stopped at, from the target [m]", "carrier_stop_target_distance_m"),
    ("carrier braking distance [m]", "carrier_braking_distance_m"),
    ("final passenger-target distance [m]", "final_passenger_target_distance_m"),
    ("max passenger speed [m/s]", "max_passenger_speed_m_s"),
    *RECOVERY_ROWS,
    ("P1 separation", "p1"),
    ("P2 navigation", "p2"),
    ("P3 carrier avoids target", "p3"),
    ("mission outcome (exit code)", "outcome"),
]

PROPERTY_TEXT = {
    "p1": "P1 (ride within mission.dock_tolerance_m of the dock point, then separate and leave it)",
    "p2": "P2 (arrive within mission.arrival_radius_m of the target)",
    "p3": "P3 (the carrier never reaches the target)",
}


def columns(summaries: list[dict]) -> list[dict]:
    """The table's columns: a pair's summary, or with several targets one column per leg (its
    own figures, judged against its own target, and its outcome)."""
    out = []
    for s in summaries:
        legs = s.get("legs") or []
        if len(legs) < 2:
            out.append(s)
            continue
        crashed = _crashed_leg(s, legs)
        for i, leg in enumerate(legs):
            crash = {"deck_crash": s["deck_crash"], "deck_touchdown_m": s.get("deck_touchdown_m"),
                     "recovery_outcome": f"crash: {s['deck_crash']}"} if i == crashed else {}
            out.append({**leg, **recovery_cells(leg), **crash, "pair": f"{s['pair']} leg {leg['leg'] + 1}",
                        "leg_outcome": f"crash: {s['deck_crash']}" if crash else leg["outcome"],
                        "mission_exit_code": s.get("mission_exit_code")})
    return out


def outcome_text(s: dict) -> str:
    """``done (0)`` or ``<reason> (<code>)``: the mission process's own verdict, which is about
    the flight (it completed or aborted), not about P1-P3; a leg's column: the leg's outcome."""
    if "leg_outcome" in s:
        return str(s["leg_outcome"])
    code = s.get("mission_exit_code")
    phase = s.get("phase")
    if s.get("deck_crash"):
        return f"crash ({code})"
    if phase == "DONE":
        return f"done ({code})"
    if s.get("reason"):
        return f"{s['reason']} ({code})"
    return f"no summary ({code})"


def verdict_lines(summaries: list[dict]) -> list[str]:
    """One line per pair that failed, naming the properties that did not hold and why."""
    lines = []
    for s in summaries:
        if s.get("not_lockstep"):
            lines.append(f"{s['pair']}: the run was NOT lockstep ({s['not_lockstep']}): its figures prove nothing")
        if s.get("deck_crash"):
            lines.append(f"{s['pair']}: the passenger CRASHED on the carrier's deck ({s['deck_crash']}), whatever the "
                         f"mission believed (its contact: {(s.get('contact') or {}).get('horizontal_error_m')} m)")
        elif s.get("docked_again") is False:
            lines.append(f"{s['pair']}: the passenger did not dock on the carrier again ({s.get('recovery_outcome')})")
        failed = [k for k in ("p1", "p2", "p3") if not s.get(k)]
        if not failed:
            continue
        if s.get("phase") == "DONE":
            flight = "the mission completed, but"
        elif s.get("reason"):
            flight = f"the mission aborted ({s['reason']}: {s.get('detail', '')}), so"
        else:
            flight = f"the mission left no summary (exit code {s.get('mission_exit_code')}), so"
        lines.append(f"{s['pair']}: {flight} these did not hold: " + "; ".join(PROPERTY_TEXT[k] for k in failed))
    return lines


def format_table(summaries: list[dict]) -> str:
    summaries = columns(summaries)
    recovery = any("recovery_outcome" in s for s in summaries)
    deck = any("takeoff_command_jump_m_s" in s for s in summaries)  # riding on the deck (mission.ride)
    rows = [r for r in ROWS if (recovery or r[1] not in RECOVERY_KEYS) and (deck or r[1] not in DECK_KEYS)]
    width = max(len(r[0]) for r in rows)
    cells = {key: [outcome_text(s) if key == "outcome" else s.get(key) for s in summaries] for _, key in rows}
    text = {key: [f"{v:.3f}" if isinstance(v, float) else str(v) for v in values] for key, values in cells.items()}
    col = max([10] + [len(s["pair"]) for s in summaries] + [len(v) for values in text.values() for v in values])
    head = f"{'':<{width}}  " + "  ".join(f"{s['pair']:>{col}}" for s in summaries)
    lines = [head, "-" * len(head)]
    for label, key in rows:
        lines.append(f"{label:<{width}}  " + "  ".join(f"{v:>{col}}" for v in text[key]))
    return "\n".join(lines)


@click.command("demo")
@click.option("--config", type=click.Path(dir_okay=False, exists=True), default=str(DEFAULT_CONFIG), show_default=True,
              help="Mission configuration shared by every pair.")
@click.option("--realtime", is_flag=True, help="Run on wall clocks scaled by --speed (to watch a run live) instead of "
              "in lockstep on the mock vehicle's simulated time, as fast as the CPU allows (the mavlink and ros2 "
              "carriers' robots step on the carrier's clock).")
@click.option("--speed", type=click.FloatRange(min=0.1, max=100), default=10.0, show_default=True,
              help="With --realtime: speed factor of every clock (vehicle, carrier, mission), like PX4's SIH speed "
              "factor. In lockstep: the pace after a participant is lost.")
@click.option("--pairs", type=click.IntRange(1, 16), default=1, show_default=True,
              help="Number of marsupial pairs flying at once on one Zenoh network.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
              help="Where to write the flight plot (one per pair, suffixed, with --pairs > 1; a team's: the team's "
              "figure, from carrier.mcap)  [default: LOG_ROOT/flight.png]")
@click.option("--log-root", type=click.Path(file_okay=False), default="logs/demo", show_default=True,
              help="Directory for the flight logs (one sub-directory per pair).")
@click.option("--timeout", "timeout_s", type=float, default=120.0, show_default=True, help="Wall-clock limit [s].")
@click.option("--verbose-children", is_flag=True,
              help="Show the children's log output here (default: each child's log is written to <name>.log in its "
                   "pair's flight folder).")
@click.option("--carrier", "carrier_kind", type=click.Choice(["sim", "mavlink", "ros2"]), default="sim", show_default=True,
              help="The carrier robot: built-in kinematic robot; a mock PX4 Ackermann rover over MAVLink; a "
                   "ROS-2-shaped diff-drive robot over Zenoh (rmw_zenoh keys).")
@click.option("--live", is_flag=False, flag_value=DEFAULT_LIVE, default=None, metavar="[HOST:PORT]",
              help=f"Serve each pair's flight live to Foxglove: pair i on PORT + i, topics /pair<i>/... "
              f"[{DEFAULT_LIVE} when given alone]. Watch at the real pace with --realtime --speed 1.")
@click.option("--estimate-error", type=click.FloatRange(min=0.0), default=VehicleOptions.estimate_error,
              show_default=True, metavar="SCALE",
              help="The vehicles' estimates err this many times as PX4 SITL's does (1: PX4 SITL's, the closest to "
                   "real PX4; 0: exact; mock-vehicle --estimate-error).")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Pair i's vehicle draws its estimate's errors from seed SEED + i.")
def demo(config: str, realtime: bool, speed: float, pairs: int, plot_path: str | None, log_root: str, timeout_s: float,
         verbose_children: bool, carrier_kind: str, live: str | None, estimate_error: float, seed: int) -> int:
    """Fly the whole system: mock PX4 vehicle + carrier simulator + mission controller.

    Each runs as its own process, talking over real UDP (MAVLink 2) and Zenoh on loopback; no
    hardware, no PX4, no external router. Ends with a summary table and a plot; exit code 0 when
    the paper's P1-P3 held for every pair (and a passenger that returns docked again). The bus and
    each MAVLink link are signed with throwaway keys, as a real flight's must be.
    """
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    if plot_path is None:  # the plot goes with the logs it draws
        plot_path = str(Path(log_root) / "flight.png")
    address = parse_live(live) if live is not None else None
    for i, a in enumerate(live_addresses(address, pairs)):
        if a is not None:
            click.echo(f"live view of pair{i}: {a.url} (Foxglove: Open connection, Foxglove WebSocket; "
                       f"layout configs/foxglove/marsupial.json)")
    if address is not None and not is_loopback(address.host):
        click.echo(f"warning: the live views bind {address.host}, not loopback: anyone who can reach them sees "
                   "the flights", err=True)
    code, summaries = run_demo(config, speed, pairs, Path(log_root), plot_path, timeout_s, quiet=not verbose_children,
                               progress=True, carrier=carrier_kind, lockstep=not realtime, live=address,
                               seed=seed, estimate_error=estimate_error)
    click.echo("times count from the start of riding (t = 0, as in the paper)")
    click.echo(format_table(summaries))
    for line in team_lines(summaries) if summaries and "team" in summaries[0] else []:
        click.echo(line)
    for s in summaries:
        plot = f", plot {s['plot']}" if s.get("plot") else (f", no plot: {s['plot_error']}" if s.get("plot_error") else "")
        plot += f", recovery {s['recovery_plot']}" if s.get("recovery_plot") else ""
        click.echo(f"{s['pair']}: flight log {Path(log_root) / s['pair']}{plot}")
    for line in verdict_lines(summaries):
        click.echo(line, err=True)
    recovery = any("docked_again" in s for s in summaries)
    if code == 0:
        click.echo("P1-P3 held" + (", and the passenger docked again" if recovery else ""))
    elif any(s.get("not_lockstep") for s in summaries):
        click.echo("the run was NOT lockstep: its figures prove nothing", err=True)
    elif all(s.get("p1") and s.get("p2") and s.get("p3") and s["mission_exit_code"] == 0 for s in summaries):
        click.echo("P1-P3 held, but the passenger did NOT dock again", err=True)
    else:
        click.echo("P1-P3 did NOT all hold", err=True)
    return code
