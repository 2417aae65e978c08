"""Zenoh sessions and the key expressions of a marsupial pair (thin I/O: knows nothing of the law).

:func:`zenoh_config` turns a :class:`~mission.config.schema.ZenohSection` into a ``zenoh.Config``
(loopback defaults, multicast scouting off), :func:`open_session` opens it with errors a user can
act on, :func:`keys` names a pair's key expressions (see :mod:`mission.bus.bridge`) and
:func:`declare` turns Zenoh's errors on declaring an entity into :class:`BusError`.
"""
from __future__ import annotations

import json
import logging
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Literal

import zenoh

from mission.time.clock import Clock, LockstepClock
from mission.config.schema import ZenohSection
from mission.config.fields import parse_zenoh_endpoint
from mission.errors import BusError, BusPortInUse, ConfigError
from mission.port_holder import port_in_use

log = logging.getLogger("mission.bus.bridge")  # one logger name for the whole bus

#: Longest a session's close may hold up an exit [s, wall]. Zenoh's own close gives up after
#: ~10 s with ZError("close operation timed out") on a lossy link; under a slowloris of 350 TCP
#: connections on its listener one took 8.7 s here.
CLOSE_TIMEOUT_S = 3.0
_abandoned = threading.Event()  # a close was left running (close_abandoned)

Encoding = Literal["json", "cdr"]
#: The Zenoh encoding a sample of each of our carrier encodings is put with.
ZENOH_ENCODING = {"json": zenoh.Encoding.APPLICATION_JSON, "cdr": zenoh.Encoding.APPLICATION_CDR}


def congestion_for(clock: Clock) -> zenoh.CongestionControl:
    """Congestion control of the state streams (carrier state, passenger status, a robot's
    odometry and commands) for a process on ``clock``. Real time: DROP, so a congested link
    drops a state instead of stalling the sender's loop. Lockstep: BLOCK, never drop. Each step
    waits for the sample that a clock message names, so a dropped sample would hold the whole
    simulation (Zenoh drops a DROP sample that waits more than about 1 ms for room in its
    queue: docs/lockstep.md)."""
    return zenoh.CongestionControl.BLOCK if isinstance(clock, LockstepClock) else zenoh.CongestionControl.DROP


def check_encoding(encoding: str) -> None:
    """Raise :class:`ConfigError` naming ``zenoh.encoding`` unless it is "json" or "cdr"."""
    if encoding not in ZENOH_ENCODING:
        raise ConfigError("zenoh.encoding", encoding, "must be 'json' or 'cdr'")


def zenoh_config(section: ZenohSection) -> zenoh.Config:
    """The ``zenoh.Config`` a :class:`ZenohSection` describes.

    - ``config_file`` set: the file is the base and decides mode and scouting; non-empty
      ``listen``/``connect`` lists still replace its endpoints (command-line flags win).
    - otherwise: ``mode``; multicast scouting as ``multicast_scouting`` (off by default);
      endpoints loopback-only unless given: a router listens on ``tcp/127.0.0.1:7447``, a client
      connects there, a peer with no endpoints uses the loopback ``rendezvous`` (see
      ZenohSection) so two processes on one machine find each other with no router, or only an
      ephemeral loopback listener if ``rendezvous`` is None; a peer given only connect endpoints
      also listens on an ephemeral loopback port (not Zenoh's all-interfaces default). With
      multicast scouting on and no endpoints, Zenoh's own defaults apply (it listens on all
      interfaces: that is the point).

    Raises :class:`ConfigError` naming the field when Zenoh refuses a value.
    """
    if section.config_file:
        path = Path(section.config_file)
        if not path.is_file():
            raise ConfigError("zenoh.config_file", section.config_file, "file not found")
        try:
            conf = zenoh.Config.from_file(str(path))
        except zenoh.ZError as exc:
            raise ConfigError("zenoh.config_file", section.config_file, f"invalid Zenoh config: {exc}") from None
        listen, connect = section.listen, section.connect
    else:
        conf = zenoh.Config()
        _insert(conf, "mode", section.mode, "zenoh.mode")
        _insert(conf, "scouting/multicast/enabled", section.multicast_scouting, "zenoh.multicast_scouting")
        listen, connect, rendezvous = _default_endpoints(section)
        if rendezvous:
            _insert(conf, "listen/exit_on_failure", False, "zenoh.rendezvous")
    if listen:
        _insert(conf, "listen/endpoints", listen, "zenoh.listen")
    if connect:
        _insert(conf, "connect/endpoints", connect, "zenoh.connect")
    return conf


def _default_endpoints(section: ZenohSection) -> tuple[list[str], list[str], bool]:
    """The listen and connect endpoints of a section without a config file, our loopback defaults
    filled in (see :func:`zenoh_config`), and whether they are the peer rendezvous pair."""
    listen, connect = list(section.listen), list(section.connect)
    if section.mode == "router" and not listen:
        return ["tcp/127.0.0.1:7447"], connect, False
    if section.mode == "client" and not connect:
        return listen, ["tcp/127.0.0.1:7447"], False
    if section.mode == "peer" and not listen and not section.multicast_scouting:
        if not connect and section.rendezvous:
            return [section.rendezvous, "tcp/127.0.0.1:0"], [section.rendezvous], True
        # A peer given only connect endpoints would otherwise get Zenoh's default listener,
        # tcp/[::]:0 on every interface; keep it on loopback like every other default.
        return ["tcp/127.0.0.1:0"], connect, False
    return listen, connect, False


def _insert(conf: zenoh.Config, key: str, value: Any, field: str) -> None:
    try:
        conf.insert_json5(key, json.dumps(value))
    except zenoh.ZError as exc:
        raise ConfigError(field, value, f"refused by Zenoh: {exc}") from None


def describe_endpoints(section: ZenohSection) -> str:
    """One line for a user: the Zenoh mode and the endpoints this section listens on and connects
    to (as :func:`zenoh_config` resolves them)."""
    if section.config_file:
        base = f"config file {section.config_file}"
        extra = [f"listen {', '.join(section.listen)}"] if section.listen else []
        extra += [f"connect {', '.join(section.connect)}"] if section.connect else []
        return f"Zenoh {base}" + (f" ({'; '.join(extra)})" if extra else "")
    listen, connect, rendezvous = _default_endpoints(section)
    if rendezvous:
        return f"Zenoh peer, loopback rendezvous {section.rendezvous} (zenoh.rendezvous)"
    if section.mode == "peer" and not listen and not connect:
        return "Zenoh peer, multicast scouting (all interfaces)"
    parts = [f"listen {', '.join(listen)}"] if listen else []
    parts += [f"connect {', '.join(connect)}"] if connect else []
    return f"Zenoh {section.mode}, " + ("; ".join(parts) or "ephemeral loopback listener")


def _listen_in_use(section: ZenohSection, text: str) -> Exception | None:
    """A :class:`PortInUse` naming the listen endpoint (and its holder) when Zenoh's error says
    a listen address is taken, else None."""
    if "Address already in use" not in text:
        return None
    for endpoint in section.listen:
        try:
            parts = parse_zenoh_endpoint(endpoint, listen=True)
        except ValueError:  # the config refuses it at load; a section built without checks
            continue
        if parts.port is not None and parts.address in text:
            return port_in_use(f"Zenoh listen endpoint {endpoint}", parts.host, parts.port,
                               "udp" if parts.proto == "udp" else "tcp", cls=BusPortInUse)
    return None


def open_session(section: ZenohSection) -> zenoh.Session:
    """Open a Zenoh session for ``section`` (see :func:`zenoh_config`); raises :class:`BusError`
    when Zenoh cannot open it (e.g. a listen port already taken). Close it with ``close()`` or a
    ``with`` block, after undeclaring what was declared on it."""
    conf = zenoh_config(section)
    try:
        session = zenoh.open(conf)
    except zenoh.ZError as exc:
        taken = _listen_in_use(section, str(exc))
        if taken is not None:
            raise taken from None
        raise BusError(f"cannot open Zenoh session ({section.mode}, listen={section.listen}, "
                       f"connect={section.connect}): {exc}") from None
    log.info("zenoh session %s open (%s)", session.zid(), section.mode)
    return session


def close_session(session: zenoh.Session, timeout_s: float = CLOSE_TIMEOUT_S) -> bool:
    """Close ``session`` and return within ``timeout_s`` of wall time, never raising: a close
    that fails (``zenoh.ZError``) is logged; one that takes longer is logged and left to itself (a
    daemon thread; :func:`close_abandoned` then tells the process to end at once), so the
    command's own outcome and exit code stand. Returns whether this close ended (failed or not)
    within the bound."""
    done = threading.Event()
    failed: list[BaseException] = []

    def close() -> None:
        try:
            session.close()
        except Exception as exc:  # noqa: BLE001 - Zenoh's ZError, or anything its teardown raises
            failed.append(exc)
        finally:
            done.set()

    threading.Thread(target=close, name="zenoh-close", daemon=True).start()
    if not done.wait(timeout_s):
        _abandoned.set()
        log.warning("zenoh session close still running after %.1f s (wall); leaving it", timeout_s)
        return False
    if failed:
        log.warning("zenoh session close failed: %s: %s", type(failed[0]).__name__, failed[0])
    return True


def close_abandoned() -> bool:
    """Whether a :func:`close_session` left a close running: the process must then end with
    ``os._exit`` (the interpreter's shutdown would abort inside Zenoh; :func:`mission.cli.console`)."""
    return _abandoned.is_set()


@dataclass(frozen=True)
class Keys:
    """Key expressions of one marsupial pair (see the module docstring); a passenger of a team
    (``keys(pair, passenger=NAME)``) has its own status, phase and liveliness keys."""

    carrier_state: str
    carrier_alive: str
    passenger_state: str
    passenger_phase: str
    passenger_alive: str


def _name(field: str, value: str) -> str:
    if not value or any(not (ch.isalnum() or ch in "_-") for ch in value):
        raise ConfigError(field, value, "must be letters, digits, '_' or '-'")
    return value


def keys(pair: str, passenger: str | None = None) -> Keys:
    """The keys of pair ``pair`` (letters, digits, ``_`` and ``-`` only). ``passenger``: the name
    of one passenger of a team (``team.passengers[].name``): its status on
    ``marsupial/<pair>/passenger/<name>/state`` (phase, alive likewise), so the team's carrier binds
    each passenger on its own key (:func:`team_status_keys`); None: the single pair's keys."""
    root = f"marsupial/{_name('zenoh.pair', pair)}"
    own = _passenger_root(pair) if passenger is None else f"{_passenger_root(pair)}/{_name('team.passengers[].name', passenger)}"
    return Keys(
        carrier_state=f"{root}/carrier/state",
        carrier_alive=f"{root}/carrier/alive",
        passenger_state=f"{own}/state",
        passenger_phase=f"{own}/phase",
        passenger_alive=f"{own}/alive",
    )


def team_status_keys(pair: str) -> str:
    """The key expression of every team passenger's status on pair ``pair`` (one chunk per name:
    never the single pair's ``marsupial/<pair>/passenger/state``)."""
    return f"{_passenger_root(pair)}/*/state"


def _passenger_root(pair: str) -> str:
    return f"marsupial/{_name('zenoh.pair', pair)}/passenger"


def passenger_of(key: str, pair: str) -> str | None:
    """The team passenger's name a status key ``key`` of pair ``pair`` names (None: not one)."""
    head, tail = f"{_passenger_root(pair)}/", "/state"
    if not (key.startswith(head) and key.endswith(tail)):
        return None
    name = key[len(head):-len(tail)]
    return name if name and "/" not in name else None


def undeclare(*entities: Any) -> None:
    """Undeclare Zenoh entities (subscribers, publishers, tokens; None skipped) in order; one whose
    session is closed already is logged, not raised (closing must not fail half way)."""
    for entity in entities:
        if entity is None:
            continue
        try:
            entity.undeclare()
        except zenoh.ZError as exc:
            log.debug("undeclare: %s", exc)


def declare(what: str, fn: Callable[[], Any]) -> Any:
    """``fn()``, a Zenoh declaration; its ``ZError`` becomes a :class:`BusError` naming ``what``."""
    try:
        return fn()
    except zenoh.ZError as exc:
        raise BusError(f"cannot declare {what}: {exc}") from None

