"""``marsupial mock-vehicle``: run the PX4-like kinematic MAVLink vehicle in the foreground.

Also runnable as ``python -m sim.vehicle.cli ...``. SIGINT and SIGTERM stop it cleanly (exit 0).
A parent process learns the bound port from ``--port-file`` (see ``sim.vehicle.mock.spawn_process``).
"""
from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import os
import threading
from pathlib import Path
from typing import Any

import click

from mission.bus.auth import SampleSigner
from mission.bus.bridge import keys, open_session
from mission.bus.signing import pair_key
from mission.config.relnav import PassengerGnssSection, RangefinderSection
from mission.config.keys import read_key_file, read_private_key_file
from mission.config.schema import Config, ZenohSection, load_config
from mission.errors import ConfigError
from mission.lifetime import on_stop_signals
from mission.mavlink.env import read_signing_key
from sim.vehicle.mock import MockVehicle, VehicleOptions
from sim.vehicle.options import VehicleSnapshot
from sim.vehicle.faults import FaultOptions
from sim.vehicle.endpoints import parse_endpoint
from sim.vehicle.params import SPECS_BY_NAME
from sim.vehicle.physics.deck import DeckSpec
from sim.robots.truth import TruthTrack
from sim.robots.deck_follow import follow_carrier
from sim.camera.publisher import CameraPublisher

log = logging.getLogger(__name__)


def _floats(text: str, count: int, option: str) -> tuple[float, ...]:
    try:
        values = tuple(float(part) for part in text.split(","))
    except ValueError:
        values = ()
    if len(values) != count:
        raise click.BadParameter(f"expected {count} comma-separated numbers, got {text!r}", param_hint=option)
    return values


def _param(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    if not sep or name not in SPECS_BY_NAME:
        raise click.BadParameter(f"expected NAME=VALUE with NAME one of {', '.join(sorted(SPECS_BY_NAME))}; got {text!r}",
                                 param_hint="--param")
    try:
        return name, float(value)
    except ValueError:
        raise click.BadParameter(f"{name}: {value!r} is not a number", param_hint="--param") from None


def _blackout(text: str) -> tuple[float, float]:
    start, sep, duration = text.partition(":")
    try:
        window = (float(start), float(duration))
    except ValueError:
        window = (-1.0, -1.0)
    if not sep or window[0] < 0 or window[1] < 0:
        raise click.BadParameter(f"expected START:DURATION in simulated seconds, got {text!r}", param_hint="--blackout")
    return window


def signing_key_option(path: Path) -> bytes:
    """The key file of --signing-key (see :func:`mission.mavlink.env.read_signing_key`)."""
    try:
        return read_signing_key(path, field="--signing-key")
    except ConfigError as exc:
        raise click.BadParameter(f"{path}: {exc.rule}", param_hint="--signing-key") from None


def _battery_params(drain_s: float | None, min_pct: float | None) -> dict[str, float]:
    """The battery simulator's parameters of --battery-drain and --battery-min-pct."""
    if drain_s is None:
        if min_pct is not None:
            raise click.BadParameter("needs --battery-drain (the battery is simulated only with it)",
                                     param_hint="--battery-min-pct")
        return {}
    return {"SIM_BAT_ENABLE": 1, "SIM_BAT_DRAIN": drain_s, **({} if min_pct is None else {"SIM_BAT_MIN_PCT": min_pct})}


def _deck_bus(pair: str, connect: tuple[str, ...], listen: tuple[str, ...]) -> tuple[str, ZenohSection]:
    """The pair and Zenoh session of --deck (no endpoints: the other processes' loopback rendezvous)."""
    try:
        keys(pair)
        endpoints = {"connect": list(connect), "listen": list(listen)}
        return pair, ZenohSection(**endpoints, **({"rendezvous": None} if connect or listen else {}))  # type: ignore[arg-type]
    except (ConfigError, ValueError) as exc:
        raise click.BadParameter(str(exc), param_hint="--deck / --zenoh-connect / --zenoh-listen") from None


def _endpoints(mavlink_url: str, target_url: str) -> tuple[str, str]:
    """(bind, target) from --mavlink and --target; a udpout URL given to --mavlink is the target."""
    try:
        endpoint = parse_endpoint(mavlink_url, "udpin")
        parse_endpoint(target_url, "udpout")
    except ValueError as exc:
        raise click.BadParameter(str(exc)) from None
    if endpoint.scheme == "udpout":
        return "127.0.0.1:14580", f"{endpoint.host}:{endpoint.port}"
    return f"{endpoint.host}:{endpoint.port}", target_url


def _write_port_file(path: Path, port: int) -> None:
    """Write the port atomically so a reader never sees a partial number."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(f"{port}\n", encoding="ascii")
    os.replace(tmp, path)


@click.command("mock-vehicle", context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--mavlink", "mavlink_url", default="udpin:127.0.0.1:14580", show_default=True, metavar="ENDPOINT",
              help="Local UDP address to bind, in pymavlink URL form (udpin:HOST:PORT, udp://HOST:PORT or HOST:PORT; "
                   "port 0 = ephemeral). A udpout:HOST:PORT URL here sets the target instead (bind stays 14580).")
@click.option("--target", "target_url", default="udpout:127.0.0.1:14540", show_default=True, metavar="ENDPOINT",
              help="Where the onboard link sends from start-up, like PX4 SITL; it then latches on the first peer "
                   "that talks to it.")
@click.option("--gcs", "gcs_url", is_flag=False, flag_value="127.0.0.1:14550", default=None, metavar="[ENDPOINT]",
              help="Also run a GCS link sending to ENDPOINT (bare --gcs: 127.0.0.1:14550), from an ephemeral port.")
@click.option("--speed", type=click.FloatRange(min=0.0, min_open=True), default=1.0, show_default=True, metavar="FACTOR",
              help="Clock speed factor: simulated seconds per wall second. Every rate and timeout scales with it.")
@click.option("--home", default="47.397742,8.545594,488.0", show_default=True, metavar="LAT,LON,ALT",
              help="EKF origin of the local NED frame: latitude [deg], longitude [deg], altitude [m AMSL].")
@click.option("--start-ned", default="0,0,0", show_default=True, metavar="N,E,D",
              help="Start position [m] in local NED. D >= 0: on the ground; D < 0: standing on a platform at that "
                   "height (a carrier deck) until it lifts off.")
@click.option("--sysid", type=click.IntRange(1, 255), default=1, show_default=True, help="MAVLink system id.")
@click.option("--frame", type=click.Choice(["quadrotor", "rover"]), default="quadrotor", show_default=True,
              help="quadrotor: point-mass multicopter; rover: MAV_TYPE_GROUND_ROVER on the ground, Ackermann "
                   "kinematics, PX4's rover offboard rules (speed |v| towards bearing atan2(v)).")
@click.option("--param", "params", multiple=True, metavar="NAME=VALUE",
              help="Override a PX4 parameter, e.g. --param COM_OF_LOSS_T=1.0 (repeatable).")
@click.option("--battery-drain", "battery_drain_s", type=click.FloatRange(min=1.0), default=None, metavar="SECONDS",
              help="Simulate the battery as PX4 SITL's battery simulator does: armed, it drains fully in SECONDS "
                   "(SIM_BAT_ENABLE=1, SIM_BAT_DRAIN; PX4 SITL: 60). Without it the vehicle reports no battery.")
@click.option("--battery-min-pct", type=click.FloatRange(0.0, 100.0), default=None, metavar="PERCENT",
              help="With --battery-drain: the charge never falls below PERCENT (SIM_BAT_MIN_PCT; PX4 SITL: 50).")
@click.option("--deck", "deck_pair", metavar="PAIR", default=None,
              help="Learn the carrier's motion from the Zenoh state of marsupial pair PAIR (marsupial/PAIR/carrier/"
                   "state): touchdown on its moving deck, riding on it, crashes (--deck-height, --deck-radius; "
                   "docs/mock-vehicle.md). Needs --zenoh-connect or --zenoh-listen.")
@click.option("--deck-truth", is_flag=True,
              help="With --deck: follow the carrier's true state, published by a carrier flying the world's GNSS errors "
                   "on the sim-only key marsupial/PAIR/sim/carrier_truth (sim/robots/truth.py), not its erring "
                   "published state.")
@click.option("--camera", is_flag=True,
              help="With --deck and --world: render the passenger's downward camera ([vision] of the --world "
                   "configuration) from the true poses and publish its frames on marsupial/PAIR/passenger/camera for "
                   "the mission's marker feed (mission.feeds = [\"marker\"]).")
@click.option("--zenoh-private-key", "camera_private_key", type=click.Path(dir_okay=False, path_type=Path), default=None,
              metavar="FILE", help="With --camera: sign its frames with the passenger's own Ed25519 private key (the one "
                                   "`run --zenoh-private-key` is given), as a camera node beside its autopilot must on a "
                                   "signed bus.")
@click.option("--zenoh-signing-key", "camera_shared_key", type=click.Path(dir_okay=False, path_type=Path), default=None,
              metavar="FILE", help="With --camera: sign its frames with the pair's shared bus key (zenoh.signing_key_file).")
@click.option("--deck-height", type=click.FloatRange(min=0.0), default=0.0, show_default=True, metavar="METRES",
              help="With --deck: the deck's plane above the carrier's reported position [m].")
@click.option("--deck-offset", default="0,0", show_default=True, metavar="N,E",
              help="With --deck: the deck's centre from the carrier's reported position [m] north, east (a team's slot).")
@click.option("--deck-radius", type=click.FloatRange(min=0.0, min_open=True), default=0.5, show_default=True,
              metavar="METRES", help="With --deck: the deck's radius round the carrier's position [m].")
@click.option("--zenoh-connect", "zenoh_connect", multiple=True, metavar="ENDPOINT",
              help="With --deck: Zenoh endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable).")
@click.option("--zenoh-listen", "zenoh_listen", multiple=True, metavar="ENDPOINT",
              help="With --deck: Zenoh endpoint to listen on (repeatable).")
@click.option("--wind", default="0,0,0", show_default=True, metavar="N,E,D",
              help="Wind [m/s] NED: a drag force in the air (PX4's velocity integrator slowly compensates it).")
@click.option("--estimate-error", type=click.FloatRange(min=0.0), default=VehicleOptions.estimate_error, show_default=True,
              metavar="SCALE", help="The estimate errs as PX4 SITL's does (its velocity and position errors; PX4 flies "
                                    "it and reports it), this many times as much (1: PX4 SITL's; seeded by --seed). "
                                    "0: an exact estimate (--ideal).")
@click.option("--ideal", is_flag=True, help="An exact estimate (--estimate-error 0): for tests of exactness.")
@click.option("--world", "world_config", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              metavar="CONFIG", help="Take the world's errors from this configuration file: [world.passenger_gnss], "
                                     "a slow GNSS bias on the estimate (docs/relnav.md); with the feed rangefinder in "
                                     "its mission.feeds, a downward rangefinder ([world.rangefinder]) sent as "
                                     "DISTANCE_SENSOR.")
@click.option("--position-noise", type=click.FloatRange(min=0.0), default=0.0, show_default=True, metavar="METRES",
              help="Sigma [m] of Gaussian noise on the reported position (seeded by --seed).")
@click.option("--loss-in", type=click.FloatRange(0.0, 1.0), default=0.0, show_default=True, metavar="FRACTION",
              help="Fault: fraction of received datagrams dropped.")
@click.option("--loss-out", type=click.FloatRange(0.0, 1.0), default=0.0, show_default=True, metavar="FRACTION",
              help="Fault: fraction of sent datagrams dropped.")
@click.option("--latency-ms", type=click.FloatRange(min=0.0), default=0.0, show_default=True, metavar="MS",
              help="Fault: one-way latency added in each direction [ms of simulated time].")
@click.option("--jitter-ms", type=click.FloatRange(min=0.0), default=0.0, show_default=True, metavar="MS",
              help="Fault: uniform extra delay in [0, MS] per datagram [ms simulated]; may reorder datagrams.")
@click.option("--blackout", "blackouts", multiple=True, metavar="START:DURATION",
              help="Fault: no datagram in or out during this window [s simulated since start] (repeatable).")
@click.option("--refuse-arming", metavar="REASON", default=None,
              help="Fault: deny arming with this STATUSTEXT reason (a failing preflight check).")
@click.option("--refuse-offboard", metavar="REASON", default=None,
              help="Fault: reject every switch to OFFBOARD (TEMPORARILY_REJECTED) with this STATUSTEXT.")
@click.option("--lose-position", "lose_position_s", type=click.FloatRange(min=0.0), default=None, metavar="SECONDS",
              help="Fault: the position estimate is lost for good at this time [s simulated since start]; PX4 "
                   "leaves the modes that need it (failsafe Descend, shown as AUTO.LAND).")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the loss, jitter and noise draws.")
@click.option("--signing-key", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              metavar="FILE", help="Enable MAVLink 2 signing with this key (64 hex digits or 32 raw bytes): "
                                   "unsigned messages other than HEARTBEAT are rejected, everything sent is signed.")
@click.option("--port-file", type=click.Path(dir_okay=False, path_type=Path), default=None, metavar="PATH",
              help="Write the bound UDP port to PATH once listening (for a parent process).")
@click.option("--lockstep", is_flag=True, help="Own simulated time and step in lockstep with the controller on the "
              "onboard link (marsupial run --lockstep); --speed is then the pace after the controller is gone.")
@click.option("--lockstep-watchdog", "lockstep_watchdog_s", type=click.FloatRange(min=0.0, min_open=True), default=10.0,
              show_default=True, metavar="SECONDS", help="With --lockstep: a controller silent this long (wall) is gone.")
@click.option("--lockstep-max-speed", type=click.FloatRange(min=0.0, min_open=True), default=None, metavar="FACTOR",
              help="With --lockstep: at most FACTOR simulated seconds per wall second (default: as fast as it goes).")
@click.option("--status-every", type=click.FloatRange(min=0.0), default=5.0, show_default=True, metavar="SECONDS",
              help="Log a status line with mode, position and the counters every SECONDS of wall time (0: never).")
@click.option("--summary", "summary_path", type=click.Path(dir_okay=False, path_type=Path), default=None, metavar="PATH",
              help="When it stops, write the world's truth to PATH as JSON: every touchdown on the deck (where "
                   "from its true centre, how fast) and a crash (docs/mock-vehicle.md).")
def mock_vehicle(mavlink_url: str, target_url: str, gcs_url: str | None, speed: float, home: str, start_ned: str,
                 sysid: int, frame: str, params: tuple[str, ...], battery_drain_s: float | None,
                 battery_min_pct: float | None, deck_pair: str | None, deck_truth: bool, camera: bool,
                 camera_private_key: Path | None, camera_shared_key: Path | None, deck_height: float, deck_offset: str, deck_radius: float,
                 zenoh_connect: tuple[str, ...], zenoh_listen: tuple[str, ...], wind: str, estimate_error: float, ideal: bool, position_noise: float, loss_in: float,
                 loss_out: float, latency_ms: float, jitter_ms: float, blackouts: tuple[str, ...],
                 refuse_arming: str | None, refuse_offboard: str | None, lose_position_s: float | None, seed: int, signing_key: Path | None, port_file: Path | None,
                 lockstep: bool, lockstep_watchdog_s: float, lockstep_max_speed: float | None, status_every: float,
                 summary_path: Path | None, world_config: Path | None = None) -> None:
    """Run the PX4-like MAVLink vehicle until SIGINT or SIGTERM.

    By default it mirrors PX4 SITL: it binds UDP 127.0.0.1:14580, sends HEARTBEAT and the
    onboard-profile streams to 127.0.0.1:14540 from start-up, and answers the first peer that
    talks to it. MAVSDK (udpin://127.0.0.1:14540) or `marsupial run` can connect, arm it and fly
    it in OFFBOARD. Counters of received, malformed, unknown and dropped messages appear in the
    status line.
    """
    bind, target = _endpoints(mavlink_url, target_url)
    if ideal:
        given = click.get_current_context().get_parameter_source("estimate_error") is not click.core.ParameterSource.DEFAULT
        if given and estimate_error != 0.0:
            raise click.BadParameter(f"--ideal is an exact estimate; --estimate-error {estimate_error:g} is not",
                                     param_hint="--ideal / --estimate-error")
        estimate_error = 0.0
    faults = FaultOptions(loss_in=loss_in, loss_out=loss_out, latency_s=latency_ms / 1000.0, jitter_s=jitter_ms / 1000.0,
                          blackouts=tuple(_blackout(b) for b in blackouts), refuse_arming_reason=refuse_arming, seed=seed,
                          refuse_offboard_reason=refuse_offboard, position_lost_at_s=lose_position_s)
    options = VehicleOptions(
        bind=bind, target=target, gcs_target=gcs_url, speed=speed, sysid=sysid, frame=frame,
        home=_floats(home, 3, "--home"), start_ned=_floats(start_ned, 3, "--start-ned"),  # type: ignore[arg-type]
        params={**_battery_params(battery_drain_s, battery_min_pct), **dict(_param(p) for p in params)}, faults=faults,
        signing_key=signing_key_option(signing_key) if signing_key else None,
        wind_ned_m_s=_floats(wind, 3, "--wind"), position_noise_m=position_noise,  # type: ignore[arg-type]
        estimate_error=estimate_error, lockstep=lockstep, lockstep_watchdog_wall_s=lockstep_watchdog_s,
        lockstep_max_speed=lockstep_max_speed, passenger_gnss=passenger_gnss_of(world_config),
        rangefinder=rangefinder_of(world_config),
        deck=None if deck_pair is None else DeckSpec(height_m=deck_height, radius_m=deck_radius,
                                                      offset_ne_m=_floats(deck_offset, 2, "--deck-offset")))  # type: ignore[arg-type]
    run(options, port_file, status_every, deck=None if deck_pair is None else _deck_bus(deck_pair, zenoh_connect, zenoh_listen),
        summary_path=summary_path, deck_truth=deck_truth, camera=camera_of(world_config, camera, deck_pair),
        camera_signer=camera_signer(camera_private_key, camera_shared_key, deck_pair, camera))


def camera_signer(private_key: Path | None, shared_key: Path | None, pair: str | None, camera: bool) -> SampleSigner | None:
    """The signer of ``--camera``'s frames: the passenger's own Ed25519 key, or pair ``pair``'s
    shared key; None when neither is given. A bad key file or option exits 2 naming it."""
    if private_key is None and shared_key is None:
        return None
    if not camera or pair is None:
        raise click.BadParameter("signs the camera's frames: needs --camera", param_hint="--zenoh-private-key / --zenoh-signing-key")
    if private_key is not None and shared_key is not None:
        raise click.BadParameter("one key signs the frames, not two", param_hint="--zenoh-private-key / --zenoh-signing-key")
    try:
        if private_key is not None:
            return SampleSigner(read_private_key_file(private_key, "--zenoh-private-key"))
        assert shared_key is not None
        return SampleSigner(pair_key(read_key_file(shared_key, "--zenoh-signing-key"), pair))
    except ConfigError as exc:
        raise click.BadParameter(exc.rule, param_hint=exc.field) from None


def camera_of(path: Path | None, camera: bool, deck_pair: str | None) -> Config | None:
    """The configuration of ``--camera`` (``--world``'s), or None without ``--camera``."""
    if not camera:
        return None
    if path is None or deck_pair is None:
        raise click.BadParameter("needs --world CONFIG (its [vision]) and --deck PAIR (the carrier)", param_hint="--camera")
    try:
        return load_config(path)
    except ConfigError as exc:
        raise click.BadParameter(str(exc), param_hint="--world") from None


def passenger_gnss_of(path: Path | None) -> PassengerGnssSection | None:
    """``[world.passenger_gnss]`` of the configuration file ``path`` (None: no file, or no bias asked)."""
    if path is None:
        return None
    try:
        gnss = load_config(path).world.passenger_gnss
    except ConfigError as exc:
        raise click.BadParameter(str(exc), param_hint="--world") from None
    return gnss if gnss.bias_sigma_m > 0.0 else None


def rangefinder_of(path: Path | None) -> RangefinderSection | None:
    """``[world.rangefinder]`` of the configuration file ``path`` when its ``mission.feeds`` names
    ``rangefinder`` (None: no file, or no such feed)."""
    if path is None:
        return None
    try:
        cfg = load_config(path)
    except ConfigError as exc:
        raise click.BadParameter(str(exc), param_hint="--world") from None
    return cfg.world.rangefinder if "rangefinder" in cfg.mission.feeds else None


def truth(snapshot: VehicleSnapshot, estimate_error: dict[str, Any] | None = None) -> dict[str, Any]:
    """The world's truth of a flight for ``--summary``: the vehicle's simulated time [s], how its
    estimate erred (``estimate_error``: :func:`estimate_of`), whether it
    lies crashed on the deck (``crash``: why, else None) and every touchdown (time [s], horizontal
    distance from the deck's true centre [m], speeds relative to the deck [m/s], crash) and the
    vehicle's counters (what it received, accepted and refused)."""
    return {"t_s": snapshot.t_s, "estimate_error": estimate_error, "counters": snapshot.counters, "deck": {
        "crash": snapshot.crash, "on_deck": snapshot.on_deck,
        "touchdowns": [dataclasses.asdict(t) for t in snapshot.touchdowns]}}


def estimate_of(options: VehicleOptions) -> dict[str, Any]:
    """How the vehicle's estimate errs: ``scale`` times PX4 SITL's errors (0: exact), drawn from ``seed``."""
    scale = options.estimate_error if options.frame == "quadrotor" else 0.0
    return {"scale": scale, "seed": options.faults.seed}


def describe_estimate(options: VehicleOptions) -> str:
    """The start-up log's words for :func:`estimate_of`."""
    e = estimate_of(options)
    return "exact estimate" if e["scale"] == 0 else f"estimate errs {e['scale']:g}x PX4 SITL's (seed {e['seed']})"


def run(options: VehicleOptions, port_file: Path | None = None, status_every_s: float = 5.0,
        deck: tuple[str, ZenohSection] | None = None, summary_path: Path | None = None, deck_truth: bool = False,
        camera: Config | None = None, camera_signer: SampleSigner | None = None) -> None:
    """Run a vehicle until SIGINT/SIGTERM, logging a status line every ``status_every_s`` wall
    seconds; with ``deck`` (pair, Zenoh section) its deck follows that pair's carrier; with
    ``summary_path`` the world's truth (:func:`truth`) is written there when it stops."""
    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    log.setLevel(logging.INFO)
    stop = threading.Event()
    track = TruthTrack() if deck is not None else None
    deck_feed = None

    with contextlib.ExitStack() as stack:
        stack.enter_context(on_stop_signals(lambda _signum: stop.set()))
        # The deck's subscriptions (the carrier's truth and clock) before the vehicle's first hello:
        # a controller answering that hello starts the lockstep, and the carrier's first steps put
        # before this process subscribed were lost (the deck first known at 0.1 s instead of at
        # the first pass, a step given up; the camera's CameraPublisher loads OpenCV meanwhile).
        vehicle = MockVehicle(options)
        if deck is not None:
            session = open_session(deck[1])
            stack.callback(session.close)
            publisher = None
            if camera is not None:
                publisher = CameraPublisher(camera, session, deck[0], options.faults.seed, options.lockstep,
                                            signer=camera_signer)
                stack.callback(publisher.close)
            deck_feed = follow_carrier(vehicle, session, deck[0], deck_truth, track, publisher)
            stack.callback(deck_feed.close)
        stack.enter_context(vehicle)
        if port_file is not None:
            _write_port_file(port_file, vehicle.port)
        log.info("mock vehicle on UDP %d -> %s, %s, %s", vehicle.port, options.target,
                 "lockstep" if options.lockstep else f"speed {options.speed:g}", describe_estimate(options))
        while not stop.wait(status_every_s if status_every_s > 0 else None):
            log.info("%s", vehicle.status_line())
        log.info("stopping: %s", vehicle.status_line())
        if summary_path is not None:
            summary_path.parent.mkdir(parents=True, exist_ok=True)
            world = truth(vehicle.snapshot(), estimate_of(options))
            if track is not None:
                world["track"] = track.as_dict()
            if deck_feed is not None and deck_feed.aligned is not None:
                world["deck"]["carrier_steps"] = dict(deck_feed.aligned.counters)
            summary_path.write_text(json.dumps(world, indent=2) + "\n")


if __name__ == "__main__":
    from mission.lifetime import end_with_parent

    end_with_parent()
    mock_vehicle()
