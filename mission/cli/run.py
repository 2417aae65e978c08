"""``marsupial run`` (fly the mission) and ``marsupial plot`` (figures from a flight log)."""
from __future__ import annotations

import json
import math
import logging
import signal
import threading
import time
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any, Iterator, NamedTuple

import click

from mission.bus.auth import bus_auth, check_team_auth, team_bus_auth, unsigned_warning
from mission.bus.neighbours import NeighbourFeed, Roster
from mission.bus.bridge import CarrierFeed, PassengerPublisher, open_session, zenoh_config
from mission.bus.session import close_session, congestion_for
from mission.time.clock import LOST_WALL_S, Clock, LockstepClock, ScaledClock
from mission.config.required import RUN_FIELDS, require_stated
from mission.config.passenger import TeamLink, check_team_flight, chosen_passenger, team_link
from mission.config.schema import Config, load_config, with_overrides
from mission.cli.subcommands import SENSORS_GROUP, entry_points, load
from mission.controller import MissionController, MissionOutcome
from mission.interfaces import CameraSink, MeasurementSource, ShowsFrames
from mission.model import mission_model
from mission.errors import ConfigError
from mission.lifetime import on_stop_signals
from mission.bus.feeds import OffsetSource
from mission.bus.gate import GateLimits
from mission.bus.timesync import ClockPing
from mission.time.offset import SharedClock
from mission.mavlink.link import VehicleLink
from mission.mavlink.env import read_signing_key
from mission.flightdata.read import is_team_log
from mission.flightdata.writer import DEFAULT_LIVE, LiveAddress, clock_metadata, is_loopback, parse_live
from mission.record.info import mission_info
from mission.record.recorder import CLOCK_NOTE, FlightRecorder, RecordSink
from mission.record.table import FlightRecord, read_record
from mission.phases import AbortReason
from mission.report import WaitReporter, abort_hint, phase_printer, startup_lines

log = logging.getLogger(__name__)

EXIT_CODES: dict[AbortReason | None, int] = {AbortReason.GEOMETRY: 2, AbortReason.VEHICLE_LOST: 3}
EXIT_ABORT = 5


def carrier_limits(cfg: Config) -> GateLimits:
    """The carrier's own limits the feed's plausibility gate checks states against: its top
    speed (``carrier.max_speed_m_s``, or ``safety.carrier_max_speed_m_s`` if larger), its
    acceleration (``safety.carrier_max_accel_m_s2``, or ``carrier.brake_decel_m_s2`` if larger),
    and how long a new reference must keep to them (``mission.carrier_settle_s``). With ``relnav.enabled``
    the carrier's state is its GNSS fix: the position and velocity noise allowed from one state to
    the next are those of two fixes' difference, :data:`GNSS_NOISE_SIGMAS` times its standard
    deviation (``relnav.gnss_position_sigma_m``, ``relnav.gnss_velocity_sigma_m_s``, times sqrt 2)."""
    accels = [a for a in (cfg.safety.carrier_max_accel_m_s2, cfg.carrier.brake_decel_m_s2) if a is not None]
    k = GNSS_NOISE_SIGMAS * math.sqrt(2.0) if cfg.relnav.enabled else 0.0
    return GateLimits(max_speed_m_s=max(cfg.carrier.max_speed_m_s, cfg.safety.carrier_max_speed_m_s or 0.0),
                      max_accel_m_s2=max(accels) if accels else None, settle_s=cfg.mission.carrier_settle_s,
                      position_slack_m=max(GateLimits.position_slack_m, k * cfg.relnav.gnss_position_sigma_m),
                      velocity_noise_m_s=max(GateLimits.velocity_noise_m_s, k * cfg.relnav.gnss_velocity_sigma_m_s))


GNSS_NOISE_SIGMAS = 5.0  # the carrier gate's noise allowance with relnav, in standard deviations of a fix difference


FEEDS_GROUP = "marsupial.feeds"  # entry points: a measurement feed's name -> its opener (below)


def feed_openers(cfg: Config) -> dict[str, str]:
    """The opener (``"module:attribute"``) of each measurement feed ``mission.feeds`` names,
    registered in ``pyproject.toml``'s entry-point group ``marsupial.feeds``. An opener is called
    as ``open(cfg, session, clock, link=LINK)`` (``LINK``: the mission's
    :class:`~mission.mavlink.link.VehicleLink`, not opened yet, for a feed of the vehicle's own
    messages; a passenger of a team of several: ``passenger=NAME`` too, its own keys) and returns a
    :class:`~mission.interfaces.MeasurementSource`.
    :class:`ConfigError` for a name nothing registered."""
    known = entry_points(FEEDS_GROUP)
    unknown = [name for name in cfg.mission.feeds if name not in known]
    if unknown:
        simulated = sorted(set(unknown) & set(entry_points(SENSORS_GROUP)))
        only = (f"; {', '.join(simulated)}: a simulated sensor only (marsupial simulate), with no flight feed yet"
                if simulated else "")
        raise ConfigError("mission.feeds", unknown, f"no such measurement feed registered (entry points "
                          f"{FEEDS_GROUP}: {sorted(known) or 'none'}){only}")
    return {name: known[name] for name in cfg.mission.feeds}


class MissionIO(NamedTuple):
    """What a mission talks through (:func:`mission_io`)."""

    feed: CarrierFeed
    publisher: PassengerPublisher
    link: VehicleLink
    sources: tuple[MeasurementSource, ...]  # the measurement feeds of mission.feeds
    neighbours: NeighbourFeed | None  # a team's passenger: its teammates' statuses (None: no team)


@contextmanager
def mission_io(cfg: Config, clock: Clock, tlog_path: str | Path | None = None, *,
               lockstep_lost_wall_s: float = LOST_WALL_S, team: TeamLink | None = None) -> Iterator[MissionIO]:
    """Open what a mission talks through, per ``cfg``: the Zenoh session with the carrier feed,
    the passenger publisher and the measurement feeds ``mission.feeds`` names
    (:func:`feed_openers`), and the MAVLink link (opened, signing per
    ``mavlink.signing_key_file``); with a :class:`LockstepClock`, the carrier's lockstep relay
    (a state sample it names that never comes given up after ``lockstep_lost_wall_s`` [s, wall],
    :class:`~mission.bus.lockstep.ZenohRelay`). ``team``: this passenger of a team of several
    (:func:`mission.config.passenger.team_link`): its status on its own keys, and its teammates'
    heard (:class:`~mission.bus.neighbours.NeighbourFeed`). Everything is closed in reverse order on exit."""
    openers = feed_openers(cfg)
    key = read_signing_key(cfg.mavlink.signing_key_file) if cfg.mavlink.signing_key_file else None
    auth = bus_auth(cfg.zenoh) if team is None else team_bus_auth(cfg.zenoh, team.names, team.name)
    with ExitStack() as stack:
        session = open_session(cfg.zenoh)
        stack.callback(close_session, session)  # never raises, bounded: the mission's outcome stands
        offset: OffsetSource
        if isinstance(clock, LockstepClock):  # the carrier steps on our clock
            offset = SharedClock()
        else:
            ping = ClockPing(session, cfg.zenoh.pair, clock, auth)
            stack.callback(ping.close)
            offset = ping
        feed = CarrierFeed.from_section(session, cfg.zenoh, clock, max_age_s=cfg.mission.carrier_timeout_s,
                                        limits=carrier_limits(cfg), auth=auth, offset=offset)
        stack.callback(feed.close)
        publisher = PassengerPublisher(session, cfg.zenoh.pair, congestion_for(clock), auth=auth,
                                       passenger=None if team is None else team.name)
        stack.callback(publisher.close)
        neighbours = None
        if team is not None:
            neighbours = NeighbourFeed(session, cfg.zenoh.pair, team.name, team.names, clock, auth=auth,
                                       max_speed_m_s=NEIGHBOUR_SPEED_FACTOR * (cfg.safety.passenger_max_speed_m_s
                                                                               or cfg.recovery.return_speed_m_s),
                                       max_age_s=cfg.mission.carrier_timeout_s,
                                       roster={n: Roster(i, legs) for n, i, legs in zip(team.names, team.ids, team.legs)})
            stack.callback(neighbours.close)
        link = VehicleLink(cfg.mavlink.url, clock, target_system=cfg.mavlink.target_system,
                           target_component=cfg.mavlink.target_component,
                           source_system=cfg.mavlink.source_system, source_component=cfg.mavlink.source_component,
                           tlog_path=None if tlog_path is None else str(tlog_path), signing_key=key,
                           heartbeat_timeout_s=cfg.mission.heartbeat_timeout_s)
        sources: list[MeasurementSource] = []
        for target in openers.values():
            # a team passenger's feeds read its own keys (its camera beside its status)
            own = {} if team is None else {"passenger": team.name}
            source = load(target)(cfg, session, clock, link=link, **own)  # type: ignore[operator]
            stack.callback(source.close)
            sources.append(source)
        # a later passenger of a team in lockstep: the carrier brings it along, and it its vehicle
        follower = clock if isinstance(clock, LockstepClock) and team is not None and team.name != team.names[0] else None
        if follower is not None and team is not None:
            from mission.bus.lockstep import ZenohUpstream, clock_keys

            upstream = ZenohUpstream(follower, session, clock_keys(cfg.zenoh.pair, team.name), feed,
                                     published=lambda: publisher.last_seq, auth=auth)
            stack.callback(upstream.close)
        elif isinstance(clock, LockstepClock):  # before open: the vehicle's first barrier may come at once
            from mission.mavlink.lockstep import MavlinkUpstream

            MavlinkUpstream(clock, link)
        link.open()
        stack.callback(link.close)
        if follower is not None:
            from mission.mavlink.lockstep import MavlinkRelay

            follower.downstream = MavlinkRelay(link)
            stack.callback(follower.close)
        elif isinstance(clock, LockstepClock):  # step on the vehicle's time; bring the carrier along
            from mission.bus.lockstep import ZenohRelay, clock_keys

            relay = ZenohRelay(session, clock_keys(cfg.zenoh.pair), feed, publisher, alive=lambda: feed.alive,
                               alive_watchdog_wall_s=cfg.sim.lockstep_carrier_wait_wall_s, auth=auth,
                               lost_wall_s=lockstep_lost_wall_s, keepalive=clock.keepalive)
            stack.callback(relay.close)
            clock.downstream = relay
            stack.callback(clock.close)  # before the link closes: its threads wait on the clock
        yield MissionIO(feed, publisher, link, tuple(sources), neighbours)


#: A teammate reporting more than this times its speed limit (safety.passenger_max_speed_m_s) is implausible.
NEIGHBOUR_SPEED_FACTOR = 2.0


def check_config(cfg: Config) -> None:
    """What a mission needs of ``cfg`` beyond the file's own rules, checked before anything is
    opened or written: the target and limits stated in the file (:mod:`mission.config.required`),
    a 3D mission model, readable signing keys (MAVLink, bus), a Zenoh configuration Zenoh
    accepts, registered measurement feeds. Raises :class:`ConfigError` naming the field."""
    require_stated(cfg, RUN_FIELDS, "run")
    mission_model(cfg)
    feed_openers(cfg)
    if cfg.mavlink.signing_key_file:
        read_signing_key(cfg.mavlink.signing_key_file)
    bus_auth(cfg.zenoh)
    zenoh_config(cfg.zenoh)


def flight_data(cfg: Config, directory: Path, info: dict[str, Any], clock: Clock,
                live: LiveAddress | None, epoch_ns: int | None = None) -> list[RecordSink]:
    """The flight record's sinks besides the CSV: ``flight.mcap`` (with the live view at
    ``live``, if given; with the recovery's docking geometry when the mission comes home; its
    log times from ``epoch_ns``, :func:`mission.flightdata.writer.log_epoch_ns`)
    (:class:`mission.flightdata.mission_log.MissionLog`)."""
    from mission.flightdata.mission_log import MissionLog

    directory.mkdir(parents=True, exist_ok=True)
    clock_info = clock_metadata(clock, CLOCK_NOTE, "the mock vehicle's simulated time (run --lockstep)", epoch_ns)
    recovery = mission_model(cfg).recovery
    return [MissionLog(directory / "flight.mcap", info, pair=cfg.zenoh.pair, clock=clock_info, live=live,
                       docking=None if recovery is None else recovery.geometry)]


def fly(cfg: Config, *, speed: float = 1.0, log_dir: str | Path | None = None, stop: threading.Event | None = None,
        on_event=None, on_start=None, clock: Clock | None = None, live: LiveAddress | None = None,
        log_epoch_ns: int | None = None, lockstep_lost_wall_s: float = LOST_WALL_S,
        team: TeamLink | None = None) -> MissionOutcome:
    """Fly one mission with ``cfg`` (the library entry point of ``marsupial run``).

    Opens the Zenoh session and the MAVLink link (:func:`mission_io`), runs
    :class:`MissionController` and closes everything in reverse order. ``speed`` is the clock
    speed factor (simulation only). ``on_start(controller, link, feed, clock)`` is called once
    everything is open, just before the loop starts (the CLI watches the wait for the vehicle).
    ``clock`` replaces the scaled clock, e.g. a :class:`LockstepClock` (made in the calling
    thread) that steps on the mock vehicle's simulated time. The flight log gets ``flight.mcap``
    beside ``record.csv``; ``live``: also serve it to Foxglove on that address; ``log_epoch_ns``:
    the epoch of its log times (default: the wall clock at the clock's zero);
    ``lockstep_lost_wall_s``: in lockstep, how long [s, wall] a carrier state sample named but
    never received is waited for (:func:`mission_io`); ``team``: this passenger of a team of
    several (:func:`mission_io`).
    """
    check_config(cfg)
    clock = clock or ScaledClock(speed)
    directory = Path(log_dir) if log_dir else Path(cfg.mission.log_dir) / f"{time.strftime('%Y%m%d-%H%M%S')}-{cfg.zenoh.pair}"
    info = mission_info(cfg)
    sinks = flight_data(cfg, directory, info, clock, live, log_epoch_ns)
    try:
        recorder = FlightRecorder(directory, info, sinks)
        io = mission_io(cfg, clock, recorder.tlog_path, lockstep_lost_wall_s=lockstep_lost_wall_s, team=team)
        with io as (feed, publisher, link, sources, neighbours):
            for source in sources:  # a camera's frames, as its feed saw them, into the flight log
                if isinstance(source, ShowsFrames):
                    for sink in sinks:
                        if isinstance(sink, CameraSink):
                            source.show_frames_to(sink)
            controller = MissionController(cfg, link, feed, clock, publisher=publisher, recorder=recorder,
                                           on_event=on_event, stop=stop, sources=sources, neighbours=neighbours)
            if on_start is not None:
                on_start(controller, link, feed, clock)
            try:
                return controller.run()
            finally:
                clock.close()
    finally:
        for sink in sinks:  # the flight closed them; an error before it flew did not
            sink.close({}, {})


def exit_code(outcome: MissionOutcome) -> int:
    if outcome.ok:
        return 0
    return EXIT_CODES.get(outcome.reason, EXIT_ABORT)


@click.command("run")
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("--mavlink", "mavlink_url", help="MAVLink endpoint (overrides mavlink.url), e.g. udpin:127.0.0.1:14540, "
              "udpout:10.0.0.2:14540, tcp:127.0.0.1:5760, /dev/ttyACM0:921600.")
@click.option("--zenoh-listen", multiple=True, help="Zenoh endpoint to listen on, e.g. tcp/127.0.0.1:7450 (repeatable).")
@click.option("--zenoh-connect", multiple=True, help="Zenoh endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable).")
@click.option("--zenoh-mode", type=click.Choice(["peer", "client"]), help="Zenoh session mode (overrides zenoh.mode).")
@click.option("--pair", help="Name of the marsupial pair: the Zenoh key namespace marsupial/<pair>/...")
@click.option("--speed", type=click.FloatRange(min=0.01), default=1.0, show_default=True,
              help="Clock speed factor. Simulation only: must equal the mock vehicle's and carrier's --speed.")
@click.option("--lockstep", is_flag=True, help="Simulation only: step on the mock vehicle's simulated time (its "
              "--lockstep) and bring the carrier simulator (--lockstep) along; --speed is then the pace after a "
              "participant is lost.")
@click.option("--lockstep-lost-wall", "lockstep_lost_wall_s", type=click.FloatRange(min=0.05), default=LOST_WALL_S,
              show_default=True, metavar="S", help="Simulation only, with --lockstep: a carrier state sample the "
              "carrier's step names but that never reaches the mission (lost in an outage, or refused) is given up "
              "after S wall seconds and 3 calls (a test of a refused carrier flies faster with less).")
@click.option("--log-dir", type=click.Path(file_okay=False), help="Where to write the flight log (default mission.log_dir/<time>-<pair>).")
@click.option("--signing-key", "signing_key_file", type=click.Path(dir_okay=False),
              help="MAVLink 2 signing key file, 64 hex digits or 32 raw bytes (overrides mavlink.signing_key_file): "
              "everything sent is signed, and everything received must be, HEARTBEAT included.")
@click.option("--zenoh-signing-key", "bus_key_file", type=click.Path(dir_okay=False),
              help="Bus signing key file of the pair (overrides zenoh.signing_key_file): carrier states and clock "
              "messages must carry its tag; the passenger's status is signed.")
@click.option("--zenoh-private-key", "own_key_file", type=click.Path(dir_okay=False),
              help="The passenger's own Ed25519 private key (overrides zenoh.private_key_file): its statuses and "
              "clock messages are signed with it. With --zenoh-peer-key: one key per robot.")
@click.option("--zenoh-peer-key", "peer_key_file", type=click.Path(dir_okay=False),
              help="The carrier's Ed25519 public key (overrides zenoh.peer_public_key_file): carrier states and clock "
              "messages must verify with it.")
@click.option("--zenoh-public-keys", "keys_dir", type=click.Path(file_okay=False), default=None, metavar="DIR",
              help="A team's robots' Ed25519 public keys (overrides zenoh.public_keys_dir): carrier.pub and "
              "<passenger>.pub; with --zenoh-private-key (this passenger's own, the private half of its DIR/NAME.pub) "
              "one key per robot on the team's bus.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON at the end.")
@click.option("--live", is_flag=False, flag_value=DEFAULT_LIVE, default=None, metavar="[HOST:PORT]",
              help=f"Serve the flight live to Foxglove (the foxglove-sdk WebSocket server) on HOST:PORT "
              f"[{DEFAULT_LIVE} when given alone; loopback unless told otherwise]. Off by default.")
@click.option("--log-epoch-ns", type=click.IntRange(min=0), default=None, metavar="NS",
              help="Flight data log times count from this epoch [ns since the Unix epoch] (a demo gives its processes "
                   "one in lockstep) [default: the wall clock at the mission clock's zero].")
@click.option("--passenger", metavar="NAME", default=None,
              help="A file with a [team]: fly passenger NAME of team.passengers (its slot's dock offset, its system "
              "id, its targets; docs/team.md); needed when the team has several. Refused (exit 2) for a file "
              "without a [team], which describes its one passenger.")
def run(config: str, mavlink_url: str | None, zenoh_listen: tuple[str, ...], zenoh_connect: tuple[str, ...],
        zenoh_mode: str | None, pair: str | None, speed: float, lockstep: bool, log_dir: str | None,
        signing_key_file: str | None, bus_key_file: str | None, own_key_file: str | None, peer_key_file: str | None,
        keys_dir: str | None, as_json: bool, live: str | None, log_epoch_ns: int | None, lockstep_lost_wall_s: float,
        passenger: str | None = None) -> int:
    """Fly the marsupial mission described by CONFIG on a PX4 vehicle.

    The passenger takes off from the carrier, joins the dock point, rides while the carrier
    approaches the target, separates smoothly when the carrier is within b*c of it, flies to the
    target and ends in Hold or Land (mission.final_action). Carrier states arrive over Zenoh;
    velocity setpoints go to the vehicle over MAVLink 2 in OFFBOARD mode.

    \b
    Phase changes are printed as they happen. On Ctrl-C or SIGTERM the vehicle is put in Hold
    (never disarmed in the air) and the program exits once it shows Hold.
    Until the vehicle and the carrier are both seen it says what it waits for, with a countdown
    to mission.connect_timeout_s. Phase lines show the mission clock and, from the start of
    riding, t (the paper's t = 0; summary.json and plots count from there).
    Exit codes: 0 mission complete; 2 bad configuration or geometry that breaks the paper's
    assumptions (nothing was sent to the vehicle); 3 vehicle lost (or never found); 4 Zenoh
    cannot start; 5 other abort (the reason is printed: pilot_override, vehicle_failsafe,
    carrier_lost, position_lost, arming_refused, offboard_refused, interrupted, timeout);
    6 a port to bind is in use (the holder is named).
    """
    cfg = load_config(config)
    overrides: dict[str, Any] = {"mavlink.url": mavlink_url, "zenoh.pair": pair, "zenoh.mode": zenoh_mode,
                                 "mavlink.signing_key_file": signing_key_file, "zenoh.signing_key_file": bus_key_file,
                                 "zenoh.private_key_file": own_key_file, "zenoh.peer_public_key_file": peer_key_file,
                                 "zenoh.public_keys_dir": keys_dir}
    if zenoh_listen:
        overrides["zenoh.listen"] = list(zenoh_listen)
    if zenoh_connect:
        overrides["zenoh.connect"] = list(zenoh_connect)
    cfg = with_overrides(cfg, overrides)
    team = team_link(cfg, passenger)  # several passengers: this one's own keys, and its teammates heard
    check_team_auth(cfg.zenoh, len(team.names) if team is not None else 1)
    check_team_flight(cfg)
    if team is not None:
        team_bus_auth(cfg.zenoh, team.names, team.name)  # every key read, and ours matched
    cfg = chosen_passenger(cfg, passenger)  # one passenger of a [team]
    check_config(cfg)  # refused before it says anything about flying (fly checks again)
    live_address = parse_live(live) if live is not None else None
    stop = threading.Event()
    for line in startup_lines(cfg, speed):
        click.echo(line)
    if (unsigned := unsigned_warning(cfg.zenoh)) is not None:
        click.echo(unsigned, err=True)
    if live_address is not None and not is_loopback(live_address.host):
        click.echo(f"warning: the live view binds {live_address.host}, not loopback: anyone who can reach "
                   f"{live_address.url} sees the flight", err=True)

    def on_signal(signum: int) -> None:
        click.echo(f"signal {signal.Signals(signum).name}: asking the vehicle to Hold", err=True)
        stop.set()

    on_event, remember, seen = phase_printer(click.echo)

    def on_start(controller: Any, link: Any, feed: Any, clock: Any) -> None:
        remember(controller, link, feed, clock)
        for sink in controller.recorder.sinks:
            if getattr(sink, "live_port", None) is not None:
                host = live_address.host if live_address is not None else "127.0.0.1"
                click.echo(f"live view: {LiveAddress(host, sink.live_port).url} (Foxglove: Open connection, "
                           f"Foxglove WebSocket; layout configs/foxglove/marsupial.json)")
        seen["reporter"] = WaitReporter(cfg, controller, link, feed, clock).start()

    try:
        with on_stop_signals(on_signal):
            clock: Clock = LockstepClock(speed=speed, name="mission-lockstep") if lockstep else ScaledClock(speed)
            outcome = fly(cfg, speed=speed, log_dir=log_dir, stop=stop, on_event=on_event, on_start=on_start,
                          clock=clock, live=live_address, log_epoch_ns=log_epoch_ns,
                          lockstep_lost_wall_s=lockstep_lost_wall_s, team=team)
    finally:
        if seen.get("reporter") is not None:
            seen["reporter"].stop()
            seen["reporter"].clear()
    if as_json:
        click.echo(json.dumps(outcome.summary, indent=2))
    elif seen["riding_start_s"] is not None:
        click.echo("summary (times since the start of riding, t = 0):")
        keys = ("separation_time_s", "carrier_target_distance_at_separation_m", "relative_input_jump_m_s",
                "final_passenger_target_distance_m", "min_carrier_target_distance_m", "p1", "p2", "p3")
        legs = outcome.summary.get("legs") or []
        for k, leg in enumerate(legs):  # several targets: the figures are per leg (summary.json's top_level_figures)
            click.echo(f"  leg {k + 1}: " + ", ".join(f"{key} {leg.get(key)}" for key in keys if key in leg))
        for key in keys if not legs else ("min_carrier_target_distance_m",):
            click.echo(f"  {key:<42} {outcome.summary.get(key)}")
    if outcome.log_dir:
        click.echo(f"flight log: {outcome.log_dir}")
    if not outcome.ok:
        click.echo(f"mission aborted: {outcome.reason}: {outcome.detail}", err=True)
        hint = abort_hint(cfg, outcome.detail)
        if hint:
            click.echo(hint, err=True)
    return exit_code(outcome)


def _is_flight_log(directory: Path) -> bool:
    return (directory / "mission.json").is_file() or (directory / "flight.mcap").is_file()


@click.command("plot")
@click.argument("log_dir", metavar="LOG", type=click.Path(exists=True))
@click.option("--out", "out_path", type=click.Path(dir_okay=False),
              help="Output image (default LOG_DIR/flight.png; with a folder of flight logs, one per log).")
@click.option("--panels", is_flag=True, help="Instead: the panels of the Foxglove layout (configs/foxglove/"
              "marsupial.json) drawn from the flight's MCAP: 3D scene, phase, distances, command, log "
              "[default LOG_DIR/flight-panels.png].")
def plot(log_dir: str, out_path: str | None, panels: bool = False) -> int:
    """Draw the paper-style figures (trajectories; |e_pc|, |e_tc|, |e_pt| over t, the time since
    the start of riding) from a flight log written by ``marsupial run`` or ``marsupial demo``.

    \b
    LOG is a flight log directory (e.g. logs/demo/pair0: its record.csv, or its flight.mcap when
    it has no CSV), an MCAP file itself (logs/demo/pair0/flight.mcap), or a folder of flight logs
    (logs/demo: each one is plotted into its own directory). A flight that came home
    (mission.final_action = "return") also gets its recovery's figure beside it
    (flight-recovery.png: the approach in the carrier's frame, the distances with the phases
    shaded). A team's log root (the team demo's: its carrier.mcap beside one flight log per
    passenger), or that carrier.mcap itself, gets the team's figure (--out, default team.png beside
    carrier.mcap: every passenger's track from above and their distances over time, as the
    carrier heard them), and each passenger's flight its own in its directory. Exit code 2 when
    LOG holds no flight log."""
    path = Path(log_dir)
    if panels:
        from mission.flightdata.view import draw_panels

        mcap = path if path.is_file() else path / "flight.mcap"
        if not mcap.is_file() or mcap.suffix != ".mcap":
            raise ConfigError("LOG", log_dir, "--panels draws from a flight.mcap: give a flight log directory that has "
                              "one (written by `marsupial run`), or the file")
        out = draw_panels(mcap, out_path or mcap.parent / "flight-panels.png")
        click.echo(f"panels written to {out}")
        return 0
    team = path if path.is_file() else path / "carrier.mcap"
    a_team = team.is_file() and team.suffix == ".mcap" and is_team_log(team)
    if a_team:
        out = plot_team_of(team, out_path or team.parent / "team.png")
        click.echo(f"team plot written to {out}")
        if path.is_file():
            return 0
        out_path = None  # the passengers' flights: each plotted into its own directory
    if path.is_file():
        if path.suffix != ".mcap":
            raise ConfigError("LOG", log_dir, "is a file but not an MCAP flight log (flight.mcap); give it, or "
                              "the flight log directory")
        out = plot_flight(path, out_path or path.parent / "flight.png")
        click.echo(f"plot written to {out}")
        return 0
    directory = path
    if _is_flight_log(directory):
        out = plot_flight(directory, out_path or directory / "flight.png")
        click.echo(f"plot written to {out}")
        return 0
    logs = sorted(d for d in directory.iterdir() if d.is_dir() and _is_flight_log(d))
    if not logs and a_team:
        return 0
    if not logs:
        raise ConfigError("LOG_DIR", log_dir, "holds no flight log (mission.json and record.csv, or flight.mcap): give a "
                          "directory written by `marsupial run` (mission.log_dir/<time>-<pair>, printed at the end of "
                          "the run) or by the demo (logs/demo/pair0)")
    if out_path and len(logs) > 1:
        raise ConfigError("--out", out_path, f"one output file for {len(logs)} flight logs; leave --out out "
                          "(each plot goes to its own log directory) or give one log directory")
    plotted = 0
    for d in logs:
        try:
            out = plot_flight(d, out_path or d / "flight.png")
        except ConfigError as exc:  # one aborted flight does not hide the others
            click.echo(f"{d}: no plot: {exc.rule}", err=True)
            continue
        click.echo(f"plot written to {out}")
        plotted += 1
    if not plotted:
        raise ConfigError("LOG_DIR", log_dir, f"none of its {len(logs)} flight logs has a flight to plot")
    return 0


def plot_flight(log_dir: Path, out_path: str | Path) -> Path:
    """The paper-style figure of one flight log (a directory, or its flight.mcap); times from
    the start of riding (t = 0)."""
    from mission.plots import plot_legs, plot_run, record_trajectories

    if log_dir.is_dir() and not (log_dir / "record.csv").is_file() and not (log_dir / "flight.mcap").is_file():
        raise ConfigError("LOG_DIR", str(log_dir), "has mission.json but no record.csv: the flight never started")
    rec = read_record(log_dir)
    name = log_dir.name if log_dir.is_dir() else f"{log_dir.parent.name}/{log_dir.name}"
    tr = record_trajectories(rec, f"flight {name}", whole_flight=True)
    if tr is None:
        raise ConfigError("LOG_DIR", str(log_dir), "the record holds no tick with both vehicle and carrier positions "
                          "(the mission ended before it flew: see its summary.json)")
    out = plot_run(tr, out_path)
    plot_legs(rec, Path(out), f"flight {name}")
    plot_recovery_of(rec, out, f"flight {name}")
    return out


def plot_team_of(carrier_mcap: str | Path, out_path: str | Path) -> Path:
    """The team's figure (:func:`mission.plots.plot_team`) of a team's ``carrier.mcap``."""
    from mission.flightdata.read import read_team
    from mission.plots import plot_team

    mcap = Path(carrier_mcap)
    return plot_team(read_team(mcap), out_path, f"team {mcap.parent.name}: as its carrier heard it")


def plot_recovery_of(rec: FlightRecord, beside: Path, title: str) -> Path | None:
    """A flight that came home: its recovery's figure beside ``beside`` (``<stem>-recovery<suffix>``);
    None for a flight without a recovery."""
    from mission.plots import plot_recovery, recovery_track

    track = recovery_track(rec, title)
    if track is None:
        return None
    return plot_recovery(track, beside.with_stem(f"{beside.stem}-recovery"))
