"""``marsupial demo --config FILE`` with a ``[team]`` of several passengers: one carrier, one mock
vehicle per passenger, one ``marsupial run --passenger NAME`` per passenger, on one Zenoh network.

- the carrier (``marsupial carrier FILE``) serves the whole team (:mod:`mission.carrier.team_bus`);
- each passenger's mock vehicle has its own UDP ports and its own MAVLink system id
  (``team.passengers[].system_id``), stands on its own slot (``--deck-offset``, ``--deck-height``:
  ``team.slots[].offset_ned_m``) and follows the carrier's state;
- each passenger's mission hears its teammates' statuses and the carrier's announced target.

The bus is signed one key per robot: a throwaway Ed25519 key pair for the carrier and for each
passenger, the public halves in one private directory (``zenoh.public_keys_dir``, :func:`team_keys`),
each process given its own private key (docs/team.md). The MAVLink links are signed with a
throwaway key as the pair demo's are.

Clocks: wall clocks scaled by ``speed`` (``--realtime``). Lockstep is the mock vehicle's simulated
time, one vehicle per clock; several vehicles would need one time for them all, which is not built,
so a team always flies on the scaled clocks, and its figures depend on the machine's load.
"""
from __future__ import annotations

import json
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from mission.bus.bridge import open_session
from mission.bus.session import close_session
from mission.config.passenger import check_team_flight, passenger_config
from mission.config.schema import Config, ZenohSection, load_config
from mission.errors import ConfigError
from mission.lifetime import supervise_children
from sim.net import child_stderr, free_port, stop_process
from sim.progress import watch_missions

#: [-] the team's clocks' speed at most: each passenger's mission ticks at 50 Hz of its clock.
TEAM_MAX_SPEED = 4.0


def child_command(*args: str) -> list[str]:
    """The command line of ``marsupial ARGS...`` run by this Python."""
    return [sys.executable, "-m", "mission.cli", *args]


def _csv(values: Any) -> str:
    return ",".join(repr(float(v)) for v in values)


def team_keys(stack: ExitStack, names: list[str]) -> Path:
    """A private temporary directory (removed when ``stack`` closes) holding a fresh Ed25519 key pair
    per robot of a team whose passengers are ``names``: ``<robot>.key`` (mode 0600) and
    ``<robot>.pub`` for :data:`mission.bus.auth.CARRIER` and each name (``zenoh.public_keys_dir``)."""
    from mission.bus.auth import CARRIER, public_key_path
    from mission.config.keys import write_key_pair

    folder = Path(tempfile.mkdtemp(prefix="marsupial-team-keys-"))
    stack.callback(shutil.rmtree, folder, True)
    for robot in (CARRIER, *names):
        write_key_pair(folder / f"{robot}.key", public_key_path(folder, robot))
    return folder


def _signed_as(keys: Path | None, robot: str) -> list[str]:
    """The options that sign robot ``robot``'s bus with its own key of the team's ``keys`` (none: unsigned)."""
    return [] if keys is None else ["--zenoh-public-keys", str(keys), "--zenoh-private-key", str(keys / f"{robot}.key")]


def start_team(cfg: Config, config: str, zenoh_ep: str, speed: float, log_root: Path, stack: ExitStack, quiet: bool,
               keys: Path | None, mav_key: Path | None, seed: int, estimate_error: float,
               run_type: Any, lockstep: bool = True) -> tuple[subprocess.Popen, list[Any]]:
    """Start the team's carrier and, per passenger, its vehicle and its mission; register their
    cleanup on ``stack``. ``keys``: the team's key directory (:func:`team_keys`; None: unsigned).
    ``run_type``: the demo's record of one passenger's processes
    (:class:`sim.demo.PairRun`, one per passenger, named after it). ``quiet``: each child's log goes
    to ``<child>.log`` beside its flight (the carrier's in ``log_root``), else to our stderr.
    Returns the carrier and the runs."""
    from mission.bus.auth import CARRIER

    pair = cfg.zenoh.pair
    mav_signed = ["--signing-key", str(mav_key)] if mav_key is not None else []
    mode = ["--lockstep"] if lockstep else []
    epoch = ["--log-epoch-ns", str(time.time_ns())] if lockstep else []  # one simulated clock: one epoch
    carrier = subprocess.Popen(child_command("carrier", config, "--speed", str(speed), "--zenoh-connect", zenoh_ep, "--summary",
                                    str(log_root / "carrier.json"), "--mcap", str(log_root / "carrier.mcap"),
                                    "--backend", "sim", *_signed_as(keys, CARRIER), *mode, *epoch),
                               stderr=child_stderr(stack, log_root if quiet else None, "carrier"))
    stack.callback(stop_process, carrier)
    runs = []
    for i, p in enumerate(cfg.team.passengers):
        slot = cfg.team.slots[cfg.team.slot_index(p.slot)].offset_ned_m
        run = run_type(name=p.name, log_dir=log_root / p.name)
        port = free_port(socket.SOCK_DGRAM)
        start = [c + o for c, o in zip(cfg.scenario.carrier_start, slot)]
        vehicle = subprocess.Popen(child_command("mock-vehicle", "--mavlink", "udpin:127.0.0.1:0", "--target",
                                        f"udpout:127.0.0.1:{port}", "--sysid", str(p.system_id), "--speed", str(speed),
                                        "--start-ned", _csv(start), "--deck", pair, "--deck-height", repr(-float(slot[2])),
                                        "--deck-offset", _csv(slot[:2]), "--zenoh-connect", zenoh_ep, "--summary",
                                        str(run.log_dir / "vehicle.json"), "--estimate-error", str(estimate_error),
                                        "--seed", str(seed + i), *mav_signed, *mode),
                                   stderr=child_stderr(stack, run.log_dir if quiet else None, "vehicle"))
        stack.callback(stop_process, vehicle)
        mission = subprocess.Popen(child_command("run", config, "--passenger", p.name, "--mavlink", f"udpin:127.0.0.1:{port}",
                                        "--zenoh-connect", zenoh_ep, "--speed", str(speed), "--log-dir", str(run.log_dir),
                                        *_signed_as(keys, p.name), *mav_signed, *mode, *epoch), stdout=subprocess.PIPE,
                                   stderr=child_stderr(stack, run.log_dir if quiet else None, "mission"), text=True)
        stack.callback(stop_process, mission, 30.0)
        run.procs = {"vehicle": vehicle, "mission": mission}
        runs.append(run)
    return carrier, runs


def run_team_demo(config: str, speed: float, log_root: Path, timeout_s: float, *, quiet: bool = True,
                  progress: bool = True, signed: bool = True, seed: int = 0, estimate_error: float = 1.0,
                  pairs: int = 1, carrier: str = "sim", live: Any = None, lockstep: bool = False,
                  plot_path: str | None = None) -> tuple[int, list[dict]]:
    """Fly ``config``'s team once on scaled wall clocks (at most :data:`TEAM_MAX_SPEED`); return
    the demo's exit code (:func:`sim.demo.exit_code`) and each passenger's summary, with the team's
    figures (``team``: the carrier's closest approach to every target, each passenger's closest
    teammate). What a team's demo does not fly is refused before anything starts
    (:class:`ConfigError` naming the option): several ``pairs``, a ``carrier`` other than the
    built-in robot, a ``live`` view. ``lockstep`` asked for: said on stderr, flown on the scaled clocks.
    ``plot_path``: where the team's figure goes (:func:`mission.plots.plot_team`, from the
    carrier's ``carrier.mcap``; None or empty: none)."""
    from sim.demo import PairRun, throwaway_key

    for option, value, ok in (("--pairs", pairs, pairs == 1), ("--carrier", carrier, carrier == "sim"),
                              ("--live", live, live is None)):
        if not ok:
            raise ConfigError(option, value, "a team's demo flies one team on the built-in carrier, with no live view "
                              "(not built)")
    cfg = load_config(config)
    check_team_flight(cfg)
    speed = speed if lockstep else min(speed, TEAM_MAX_SPEED)
    supervise_children()  # a demo killed outright takes its processes with it
    log_root.mkdir(parents=True, exist_ok=True)
    zenoh_ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    with ExitStack() as stack:
        keys = team_keys(stack, [p.name for p in cfg.team.passengers]) if signed else None
        mav_key = throwaway_key(stack, "mavlink.key") if signed else None
        router = open_session(ZenohSection(mode="router", listen=[zenoh_ep]))
        stack.callback(close_session, router)
        carrier, runs = start_team(cfg, config, zenoh_ep, speed, log_root, stack, quiet, keys, mav_key, seed,
                                   estimate_error, PairRun, lockstep)
        readers = watch_missions(runs, timeout_s, progress, stack)
        for r in runs:
            try:
                r.procs["mission"].wait(timeout=30.0)
            except subprocess.TimeoutExpired:
                r.procs["mission"].kill()
        stop_process(carrier)  # writes carrier.json
        for reader in readers:
            reader.join(timeout=5.0)
    return team_summaries(cfg, config, log_root, runs, speed, lockstep, plot_path)


def team_summaries(cfg: Config, config: str, log_root: Path, runs: list[Any], speed: float,
                   lockstep: bool, plot_path: str | None = None) -> tuple[int, list[dict]]:
    """Each passenger's summary with its exit code, the deck's truth and the team's figures."""
    from sim.demo import deck_truth, exit_code, not_lockstep, recovery_cells

    path = log_root / "carrier.json"
    carrier = json.loads(path.read_text()) if path.exists() else {}
    summaries = []
    for r in runs:
        s = r.summary()
        s["pair"] = r.name
        s["mission_exit_code"] = r.procs["mission"].returncode
        s.update(deck_truth(r.log_dir / "vehicle.json"))
        s.update(recovery_cells(s))
        if lockstep:
            s["carrier_lockstep"] = carrier.get("lockstep")
            s["not_lockstep"] = not_lockstep(s)
        own = passenger_config(cfg, r.name)
        s["slot_offset_ned_m"] = list(own.mission.dock_offset_ned_m)
        s["closest_teammate"] = (s.get("neighbours") or {}).get("closest")
        summaries.append(s)
    team = {"speed": speed, "clocks": "lockstep, the first passenger's vehicle's time" if lockstep else
            "scaled wall clocks (--realtime)",
            "carrier_closest_each_target_m": carrier.get("closest_each_target_m"),
            "carrier_hand_overs": carrier.get("hand_overs"),
            "keep_out_m": carrier.get("guard_radius_m"),
            "separation_m": cfg.safety.passenger_separation_m,
            "carrier_closest_pair": carrier.get("closest_pair")}
    if plot_path and (log_root / "carrier.mcap").exists():
        from mission.cli.run import plot_team_of
        from mission.errors import MarsupialError

        try:
            team["plot"] = str(plot_team_of(log_root / "carrier.mcap", plot_path))
        except MarsupialError as exc:
            team["plot_error"] = str(exc)
    (log_root / "team.json").write_text(json.dumps({"team": team, "passengers": summaries}, indent=2, default=str) + "\n")
    for s in summaries:
        s["team"] = team
    return exit_code(summaries), summaries


def team_lines(summaries: list[dict]) -> list[str]:
    """The team's figures as lines: each passenger's closest teammate, the closest pair as the
    carrier heard them, the carrier's closest approach to each target against its keep-out, the
    team's figure."""
    if not summaries:
        return []
    team = summaries[0]["team"]
    lines = [f"team flown on {team['clocks']}" + ("" if team["clocks"].startswith("lockstep") else
                                                  f", speed x{team['speed']:g}")]
    for s in summaries:
        c = s.get("closest_teammate") or {}
        lines.append(f"{s['pair']}: closest teammate {c.get('distance_m')} m at t {c.get('t_s')} s (phases "
                     f"{c.get('phases')}), against safety.passenger_separation_m = {team['separation_m']:g} m")
    pair = team.get("carrier_closest_pair") or {}
    lines.append(f"carrier: closest pair as heard {pair.get('distance_m')} m at t {pair.get('t_s')} s ({pair.get('names')}, "
                 f"phases {pair.get('phases')})")
    closest = team.get("carrier_closest_each_target_m") or []
    lines.append("carrier closest approach to each target [m]: "
                 + ", ".join(f"{k}: {d:.3f}" if d is not None else f"{k}: -" for k, d in enumerate(closest))
                 + f" (P3 guard radius {team.get('keep_out_m')} m); hand-overs {team.get('carrier_hand_overs')}")
    if team.get("plot") or team.get("plot_error"):
        lines.append(f"team plot {team['plot']}" if team.get("plot") else f"no team plot: {team['plot_error']}")
    return lines
