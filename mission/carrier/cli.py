"""``marsupial carrier CONFIG``: the carrier-side controller on the backend of ``carrier.backend``.

``sim`` (the built-in kinematic robot), ``mavlink`` (a PX4 rover or boat) or ``ros2`` (a ROS 2
robot through Zenoh). :func:`main` is the library entry point; the click command only parses.
"""
from __future__ import annotations

import json
import logging
import signal
import threading
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import click
import numpy as np

from mission.carrier.backends import KINDS, describe, open_backend
from mission.carrier.controller import CarrierController
from mission.bus.auth import CARRIER, BusAuth, bus_auth, check_team_auth, team_bus_auth, unsigned_warning
from mission.bus.bridge import describe_endpoints, keys, open_session
from mission.bus.session import close_session
from mission.time.clock import Clock, LockstepClock, ScaledClock
from mission.config.required import CARRIER_FIELDS, require_stated
from mission.config.passenger import check_team_flight, has_team, sole_passenger
from mission.config.schema import Config, load_config, with_overrides
from mission.cli.subcommands import entry_points, load
from mission.errors import ConfigError
from mission.lifetime import on_stop_signals
from mission.bus.lockstep import Downstreams, LastSeq, ZenohRelay, ZenohUpstream, clock_keys
from mission.bus.timesync import ClockEcho

log = logging.getLogger(__name__)


def main(cfg: Config, speed: float = 1.0, duration_s: float | None = None, stop_event: threading.Event | None = None,
         summary_path: str | Path | None = None, lockstep: bool = False, mcap_path: str | Path | None = None,
         log_epoch_ns: int | None = None) -> int:
    """Open the session of ``cfg.zenoh`` and the backend, run the controller until stopped;
    write the summary (JSON) to ``summary_path`` if given, and the carrier's flight data to the
    MCAP file ``mcap_path`` (:class:`mission.flightdata.carrier_log.CarrierLog`); return exit code 0.

    ``lockstep`` (simulation): step on the mission controller's clock relay
    (:mod:`mission.bus.lockstep`) instead of a wall clock scaled by ``speed``; ``speed`` is then the
    pace once the relay falls silent.

    SIGINT/SIGTERM set the stop event when called from the main thread. Raises
    :class:`~mission.errors.ConfigError` if the file does not state the target and the carrier's
    limits (:mod:`mission.config.required`) or the bus key is unreadable,
    :class:`~mission.errors.BusError` if Zenoh cannot open, :class:`~mission.errors.LinkError`
    if the vehicle link cannot open.
    """
    require_stated(cfg, CARRIER_FIELDS, "carrier")  # before anything is opened
    bus_auth(cfg.zenoh)
    stop = stop_event or threading.Event()
    clock: Clock = LockstepClock(speed=speed, name="carrier-lockstep") if lockstep else ScaledClock(speed)

    def _stop(signum: int) -> None:
        log.info("carrier: %s, stopping", signal.Signals(signum).name)
        stop.set()
        clock.close()  # a lockstep sleep ends now

    with on_stop_signals(_stop):
        with ExitStack() as stack:
            session = open_session(cfg.zenoh)
            stack.callback(close_session, session)  # never raises, bounded: the exit code stands
            backend = with_world(cfg, open_backend(cfg, clock, session), clock, session)
            stack.callback(backend.close)
            steps = open_flight_data(cfg, clock, mcap_path, stack, log_epoch_ns)
            with CarrierController(cfg, clock, session, backend, steps=steps) as ctl:
                echo = ClockEcho(session, ctl.pair, clock, ctl.auth)  # the passenger measures our clock's offset
                stack.callback(echo.close)
                if steps is not None:
                    steps.set_counters(lambda: ctl.passenger.counters)
                if isinstance(clock, LockstepClock):
                    upstream = ZenohUpstream(clock, session, clock_keys(ctl.pair), ctl.passenger,
                                             published=lambda: ctl.seq - 1, auth=first_passenger_auth(ctl))
                    stack.callback(upstream.close)
                    clock.downstream = team_relays(cfg, ctl, session, clock, backend.lockstep_relay(session), stack)
                    stack.callback(clock.close)
                try:
                    ctl.run(stop, duration_s)
                finally:
                    summary = ctl.summary()
                    report = getattr(backend, "report", None)
                    if report is not None:
                        summary[backend.name] = report()
                    summary["clock_echo"] = dict(echo.counters)
                    if isinstance(clock, LockstepClock):
                        summary["lockstep"] = clock.counters
                    log.info("carrier %s stopped in mode %s; closest approach to the target %s m, braking distance %s m",
                             ctl.pair, summary["mode"], _fmt(summary["closest_target_distance_m"]),
                             _fmt(summary["braking_distance_m"]))
                    if summary_path is not None:
                        Path(summary_path).parent.mkdir(parents=True, exist_ok=True)
                        Path(summary_path).write_text(json.dumps(summary, indent=2, default=_jsonable) + "\n")
    return 0


def team_relays(cfg: Config, ctl: CarrierController, session: Any, clock: LockstepClock, robot: Any,
                stack: ExitStack) -> Any:
    """What the carrier brings along in lockstep: its own robot (``robot``, None: none) and, with a
    team of several, every passenger but the first (whose vehicle owns the time), each on its own
    clock keys (:func:`~mission.bus.lockstep.clock_keys`): its step waits for the status it names,
    and its call names the carrier's last state (docs/team.md, "The team on the bus")."""
    if ctl.team is None:
        return robot
    relays = [robot]
    for name, feed in list(zip(ctl.team.names, ctl.team.feeds))[1:]:
        relay = ZenohRelay(session, clock_keys(ctl.pair, name), feed, LastSeq(lambda: ctl.seq - 1),
                           alive=_alive_of(feed), alive_watchdog_wall_s=cfg.sim.lockstep_carrier_wait_wall_s,
                           auth=None if ctl.auth is None else ctl.auth.for_peer(name), name=f"passenger {name}",
                           keepalive=clock.keepalive)
        stack.callback(relay.close)
        relays.append(relay)
    return Downstreams(relays)


def first_passenger_auth(ctl: CarrierController) -> BusAuth | None:
    """The carrier's keys for the lockstep calls of the passenger whose vehicle owns the time (a
    team's first: only its own key verifies them; a pair's: the peer's)."""
    if ctl.auth is None or ctl.team is None:
        return ctl.auth
    return ctl.auth.for_peer(ctl.team.names[0])


def _alive_of(feed: Any) -> Any:
    return lambda: feed.alive


WORLD_GROUP = "marsupial.world"  # entry points: the world's errors a simulated flight adds (pyproject.toml)


def with_world(cfg: Config, backend: Any, clock: Clock, session: Any) -> Any:
    """``backend`` as the world of ``cfg`` makes it (simulation only): with
    ``world.carrier_gnss.enabled`` wrapped by the entry point ``carrier_gnss`` of
    :data:`WORLD_GROUP` (the simulator's, called ``(cfg, backend, session, clock)``): the carrier
    steers on and publishes its state as an erring GNSS gives it. Else ``backend`` itself.
    :class:`ConfigError` when the errors are asked for and no simulator registered them."""
    if not cfg.world.carrier_gnss.enabled:
        return backend
    known = entry_points(WORLD_GROUP)
    if "carrier_gnss" not in known:
        raise ConfigError("world.carrier_gnss.enabled", True, f"the simulator's carrier GNSS errors are not installed "
                          f"(entry point {WORLD_GROUP}: carrier_gnss)")
    log.info("carrier %s: the world's carrier GNSS errors on (world.carrier_gnss, seed %d)", cfg.zenoh.pair,
             cfg.world.carrier_gnss.seed)
    return load(known["carrier_gnss"])(cfg, backend, session, clock)  # type: ignore[operator]


def open_flight_data(cfg: Config, clock: Clock, mcap_path: str | Path | None, stack: ExitStack,
                     epoch_ns: int | None = None) -> Any:
    """The carrier's MCAP log at ``mcap_path`` (None: none), closed by ``stack``; its log times
    from ``epoch_ns`` (:func:`mission.flightdata.writer.log_epoch_ns`)."""
    if mcap_path is None:
        return None
    from mission.flightdata.carrier_log import CarrierLog
    from mission.flightdata.writer import clock_metadata

    Path(mcap_path).parent.mkdir(parents=True, exist_ok=True)
    note = "times are the carrier's clock [s] (in lockstep the mission's, relayed to the carrier)"
    steps = CarrierLog(mcap_path, pair=cfg.zenoh.pair, target=cfg.scenario.target,
                       clock=clock_metadata(clock, note, "the mission controller's relay of the mock vehicle's time",
                                            epoch_ns), team=_team_metadata(cfg))
    stack.callback(steps.close)
    return steps


def _team_metadata(cfg: Config) -> dict[str, Any] | None:
    """A team's ``carrier.mcap`` ``team`` record (:func:`mission.flightdata.carrier_log.team_metadata`);
    None for a single pair."""
    if not has_team(cfg):
        return None
    from mission.flightdata.carrier_log import team_metadata

    owners = {k: p.name for p in cfg.team.passengers for k in p.targets}
    targets = cfg.scenario.legs()
    return team_metadata([p.name for p in cfg.team.passengers], targets, [owners[k] for k in range(len(targets))],
                         cfg.law.params().separation_distance_m, cfg.safety.passenger_separation_m,
                         cfg.safety.passenger_separation_max_age_s)


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


@click.command("carrier", context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("--backend", type=click.Choice(list(KINDS)), default=None,
              help="The carrier robot: " + ", ".join(f"{k.name} ({k.summary})" for k in KINDS.values())
              + " [default: carrier.backend, sim].")
@click.option("--speed", type=click.FloatRange(min=0, min_open=True), default=1.0, show_default=True,
              help="Clock speed factor (like PX4's SIH speed factor); use the mock vehicle's.")
@click.option("--pair", default=None, help="Pair name: keys marsupial/<pair>/... [default: zenoh.pair]")
@click.option("--zenoh-listen", "listen", multiple=True, metavar="ENDPOINT",
              help="Zenoh listen endpoint, e.g. tcp/127.0.0.1:7448 (repeatable; replaces zenoh.listen).")
@click.option("--zenoh-connect", "connect", multiple=True, metavar="ENDPOINT",
              help="Zenoh endpoint to connect to (repeatable; replaces zenoh.connect).")
@click.option("--encoding", type=click.Choice(["json", "cdr"]), default=None,
              help="Carrier state encoding: JSON or ROS 2 nav_msgs/Odometry CDR [default: zenoh.encoding].")
@click.option("--rate", type=click.FloatRange(min=0, min_open=True, max=1000), default=None, metavar="HZ",
              help="Control/publish rate in simulated Hz [default: carrier.rate_hz, 30].")
@click.option("--mavlink", "mavlink_url", default=None, metavar="URL",
              help="MAVLink URL of the carrier vehicle (mavlink backend) [default: carrier.mavlink.url].")
@click.option("--target-system", type=click.IntRange(1, 255), default=None,
              help="MAVLink system id of the carrier vehicle [default: carrier.mavlink.target_system].")
@click.option("--kinematics", type=click.Choice(["holonomic", "diff_drive", "ackermann"]), default=None,
              help="What the carrier can follow (tracking law) [default: carrier.kinematics].")
@click.option("--offset-ned", default=None, metavar="N,E,D",
              help="Where the vehicle's local (mavlink) or odom (ros2) frame origin sits in the shared frame [m].")
@click.option("--ros2-namespace", default=None, help="ROS namespace of the robot (ros2) [default: carrier.ros2.namespace].")
@click.option("--key-form", type=click.Choice(["ros2dds", "rmw_zenoh"]), default=None,
              help="ROS 2 key form (ros2) [default: carrier.ros2.key_form].")
@click.option("--cmd-vel-type", type=click.Choice(["Twist", "TwistStamped"]), default=None,
              help="ROS 2 velocity command type (ros2) [default: carrier.ros2.cmd_vel_type].")
@click.option("--duration", type=click.FloatRange(min=0, min_open=True), default=None, metavar="S",
              help="Stop after this many simulated seconds [default: run until SIGINT/SIGTERM].")
@click.option("--lockstep", is_flag=True, help="Simulation: step on the mission controller's lockstep clock "
              "(marsupial run --lockstep, the mock vehicle's simulated time) instead of a scaled wall clock.")
@click.option("--summary", "summary_path", type=click.Path(dir_okay=False), default=None, metavar="PATH",
              help="Write the carrier's summary (closest approach, braking distance, guard activity) as JSON.")
@click.option("--mcap", "mcap_path", type=click.Path(dir_okay=False), default=None, metavar="PATH",
              help="Write the carrier's flight data (its pose, mode, commands, P3 guard) to this MCAP file.")
@click.option("--log-epoch-ns", type=click.IntRange(min=0), default=None, metavar="NS",
              help="Flight data log times count from this epoch [ns since the Unix epoch] (a demo gives its processes "
                   "one in lockstep) [default: the wall clock at the carrier clock's zero].")
@click.option("--zenoh-signing-key", "bus_key_file", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="Bus signing key file of the pair (overrides zenoh.signing_key_file): the carrier's state is signed, "
                   "the passenger's status must carry its tag.")
@click.option("--zenoh-private-key", "own_key_file", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="The carrier's own Ed25519 private key (overrides zenoh.private_key_file): its state and clock "
                   "messages are signed with it. With --zenoh-peer-key: one key per robot.")
@click.option("--zenoh-peer-key", "peer_key_file", type=click.Path(dir_okay=False), default=None, metavar="FILE",
              help="The passenger's Ed25519 public key (overrides zenoh.peer_public_key_file): the passenger's status "
                   "must verify with it.")
@click.option("--zenoh-public-keys", "keys_dir", type=click.Path(file_okay=False), default=None, metavar="DIR",
              help="A team's robots' Ed25519 public keys (overrides zenoh.public_keys_dir): carrier.pub and "
                   "<passenger>.pub; with --zenoh-private-key (the carrier's own, the private half of DIR/carrier.pub) one "
                   "key per robot on the team's bus.")
def carrier_cli(config: str, backend: str | None, speed: float, pair: str | None, listen: tuple[str, ...],
                    connect: tuple[str, ...], encoding: str | None, rate: float | None, mavlink_url: str | None,
                    target_system: int | None, kinematics: str | None, offset_ned: str | None,
                    ros2_namespace: str | None, key_form: str | None, cmd_vel_type: str | None, duration: float | None,
                    lockstep: bool, summary_path: str | None, mcap_path: str | None, log_epoch_ns: int | None,
                    bus_key_file: str | None,
                    own_key_file: str | None, peer_key_file: str | None, keys_dir: str | None = None) -> int:
    """Run the carrier-side controller of CONFIG (a TOML file).

    The carrier waits until the passenger's published phase is RIDING, then drives towards
    scenario.target with the paper's law u_c = k_c e_tc (planar, CBF obstacle filter,
    carrier.max_speed_m_s, a tracking law for diff-drive/Ackermann robots), and stops when the
    phase says SEPARATED or later (scenario.carrier_mode = "remark1": keeps its velocity of that
    instant). It stops if the passenger goes silent or vanishes before separation, or if its own
    state goes stale. Whatever the passenger says, the P3 guard keeps it at least
    b c - carrier.p3_margin_m from the target.

    It publishes its state (local NED) on marsupial/<pair>/carrier/state at --rate and holds
    the token marsupial/<pair>/carrier/alive. Exit 0 on SIGINT/SIGTERM or after --duration;
    2 on a configuration error; 3 if the vehicle link cannot open; 4 if Zenoh cannot start.
    """
    cfg = load_config(config)
    chosen = backend or cfg.carrier.backend
    offset = None
    if offset_ned is not None:
        try:
            offset = [float(p) for p in offset_ned.split(",")]
        except ValueError:
            offset = []
        if len(offset) != 3:
            raise click.BadParameter(f"expected N,E,D, got {offset_ned!r}", param_hint="--offset-ned")
    cfg = with_overrides(cfg, {
        "carrier.backend": backend,
        "carrier.kinematics": kinematics,
        "carrier.mavlink.target_system": target_system,
        "carrier.ros2.namespace": ros2_namespace,
        "carrier.ros2.key_form": key_form,
        "carrier.ros2.cmd_vel_type": cmd_vel_type,
        f"carrier.{chosen if chosen != 'sim' else 'mavlink'}.offset_ned_m": offset,
        "zenoh.pair": pair,
        "zenoh.listen": list(listen) if listen else None,
        "zenoh.connect": list(connect) if connect else None,
        "zenoh.encoding": encoding,
        "carrier.rate_hz": rate,
        "carrier.mavlink.url": mavlink_url,
        "zenoh.signing_key_file": bus_key_file,
        "zenoh.private_key_file": own_key_file,
        "zenoh.peer_public_key_file": peer_key_file,
        "zenoh.public_keys_dir": keys_dir,
    })
    check_team_auth(cfg.zenoh, len(cfg.team.passengers) if has_team(cfg) else 1)
    check_team_flight(cfg)
    if not has_team(cfg) or len(cfg.team.passengers) == 1:
        cfg = sole_passenger(cfg, "driven by `marsupial carrier`")  # a team of one: its passenger's (docs/team.md)
    else:  # a team of several: one carrier serves them all (mission.carrier.team_bus), checked before anything opens
        team_bus_auth(cfg.zenoh, [p.name for p in cfg.team.passengers], CARRIER)  # every key read and matched
    require_stated(cfg, CARRIER_FIELDS, "carrier")  # refused before it says anything about flying
    click.echo(startup_line(cfg, speed), err=True)
    if (unsigned := unsigned_warning(cfg.zenoh)) is not None:
        click.echo(unsigned, err=True)
    return main(cfg, speed, duration, summary_path=summary_path, lockstep=lockstep, mcap_path=mcap_path, log_epoch_ns=log_epoch_ns)


def startup_line(cfg: Config, speed: float) -> str:
    """What ``marsupial carrier`` says at start-up: pair, backend, endpoint, mode, what it waits for."""
    k = keys(cfg.zenoh.pair)
    c = cfg.carrier
    plan = {"stop": "stops at separation", "remark1": "keeps its own plan after separation (Remark 1)"}
    robot = describe(cfg)
    start = np.round(np.asarray(cfg.scenario.carrier_start, dtype=float), 2).tolist()
    names = [p.name for p in cfg.team.passengers] if has_team(cfg) else []
    riders = (f"the passenger to ride (phase RIDING on {k.passenger_phase})" if not names else
              f"its team to ride ({', '.join(names)}: each on {keys(cfg.zenoh.pair, names[0]).passenger_phase.replace(names[0], 'NAME')})")
    return (f"carrier {cfg.zenoh.pair}: {robot} ({c.kinematics}); publishing {k.carrier_state} ({cfg.zenoh.encoding}, "
            f"{c.rate_hz:g} Hz) on {describe_endpoints(cfg.zenoh)}; mode {cfg.scenario.carrier_mode} "
            f"({plan[cfg.scenario.carrier_mode]}); P3 guard at "
            f"{cfg.law.params().separation_distance_m - c.p3_margin_m:g} m from the target"
            f"{'' if c.p3_frame == 'own' else f' in the passenger frame (its own: {c.p3_unaligned_margin_m:g} m nearer)'}"
            f"; at {start} NED [m], "
            f"waiting for {riders}; clock x{speed:g}")
