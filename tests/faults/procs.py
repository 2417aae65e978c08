"""The three real processes of a marsupial pair, for the fault matrix.

``python -m mission.cli carrier|run|mock-vehicle`` run as subprocesses, as ``marsupial demo``
starts them, talking over real UDP and Zenoh on 127.0.0.1 with test-chosen ports. The Zenoh
router is a session in the test process (so a test can restart it); a pymavlink observer sits
on the vehicle's GCS link (``--gcs``), as a ground station would, and sees mode, arming and
landed state whatever the mission does.

The vehicle starts last, once the carrier and the mission are up, so the vehicle's simulated
clock is the flight's clock: ``--blackout START:DURATION`` and ``--lose-position AT`` land at the
same point of the mission in every run. At speed 5 (the timeline measured on this machine):
the mission identifies the vehicle at once, arms at ~1 s, rides from ~4.5 s, separates at
~17 s and arrives (Hold) at ~21 s of vehicle time.
"""
from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mission.mavlink import px4
from mission.bus.bridge import open_session
from mission.config.schema import ZenohSection
from sim.net import stop_process, wait_for
from sim.vehicle.mock import spawn_process
from sim.testing.probe import Probe, connect
from tests.conftest import CONFIGS, free_port

SPEED = 5.0
DEMO = CONFIGS / "demo.toml"
FLEET_CLIENT = CONFIGS / "zenoh" / "fleet_client.json5"


def udp_bound(port: int) -> bool:
    """Is some socket bound to UDP 127.0.0.1:``port`` (Linux /proc/net/udp)?"""
    needle = f"0100007F:{port:04X}"
    with open("/proc/net/udp", encoding="ascii") as f:
        return any(line.split()[1] == needle for line in f.readlines()[1:])


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "mission.cli", *args]


class Router:
    """A Zenoh router session in this process on a loopback port chosen by the test; it watches
    the liveliness tokens of ``marsupial/**`` (present keys in :attr:`tokens`)."""

    def __init__(self) -> None:
        self.port = free_port(socket.SOCK_STREAM)
        self.endpoint = f"tcp/127.0.0.1:{self.port}"
        self.tokens: set[str] = set()
        self._lock = threading.Lock()
        self.session: Any = None
        self._sub: Any = None
        self.open()

    def _on_token(self, sample: Any) -> None:
        import zenoh

        with self._lock:
            (self.tokens.add if sample.kind == zenoh.SampleKind.PUT else self.tokens.discard)(str(sample.key_expr))

    def open(self) -> None:
        self.session = open_session(ZenohSection(mode="router", listen=[self.endpoint], rendezvous=None))
        self._sub = self.session.liveliness().declare_subscriber("marsupial/**", self._on_token, history=True)

    def close(self) -> None:
        if self.session is not None:
            self._sub.undeclare()
            self.session.close()
            self.session = None
            with self._lock:
                self.tokens.clear()

    def has(self, key: str) -> bool:
        with self._lock:
            return key in self.tokens


def fleet_config(path: Path) -> Path:
    """Write demo.toml with the fleet client Zenoh configuration (every process a client of the
    router) to ``path``."""
    text = DEMO.read_text()
    assert 'mode = "peer"' in text
    path.write_text(text.replace('mode = "peer"', f'config_file = "{FLEET_CLIENT}"'))
    return path


@dataclass
class Flight:
    """One pair of real processes. Output of each process goes to ``<dir>/<name>.out|.err``."""

    dir: Path
    router: Router
    config: Path = DEMO
    pair: str = "pair0"
    speed: float = SPEED
    vehicle_args: tuple[str, ...] = ()
    mission_args: tuple[str, ...] = ()
    carrier_args: tuple[str, ...] = ()
    mission_verbose: bool = False  # -vv: debug logging (more output to search for leaks)
    lockstep: bool = False  # the three step on the vehicle's simulated time; speed: pace once one stops
    mav_port: int = 0
    before_vehicle: Any = None  # called with the flight once carrier and mission are up, before the vehicle starts
    mission_router: Router | None = None  # the mission on a router of its own (a relay between the two); None: ``router``
    procs: dict[str, subprocess.Popen[Any]] = field(default_factory=dict)
    gcs: Probe | None = None
    _files: list[Any] = field(default_factory=list)

    @property
    def log_dir(self) -> Path:
        return self.dir / "flight"

    def _popen(self, name: str, args: list[str]) -> subprocess.Popen[Any]:
        out = open(self.dir / f"{name}.out", "ab")
        err = open(self.dir / f"{name}.err", "ab")
        self._files += [out, err]
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        proc = subprocess.Popen(args, stdout=out, stderr=err, env=env)
        self.procs[name] = proc
        return proc

    def start_carrier(self, lockstep: bool | None = None) -> None:
        """Start (or restart) the carrier; ``lockstep`` None: as the flight (False: real time at ``speed``)."""
        mode = self._mode if lockstep is None or lockstep else []
        self._popen("carrier", cli("-v", "carrier", str(self.config), "--speed", str(self.speed), "--pair", self.pair,
                                   "--zenoh-connect", self.router.endpoint, "--summary", str(self.dir / "carrier.json"),
                                   *mode, *self.carrier_args))

    @property
    def _mode(self) -> list[str]:
        return ["--lockstep"] if self.lockstep else []

    def carrier_alive(self) -> bool:
        return self.router.has(f"marsupial/{self.pair}/carrier/alive")

    def start(self) -> None:
        """Carrier and mission first; the vehicle once both are up (see the module docstring)."""
        self.mav_port = free_port(socket.SOCK_DGRAM)
        self.start_carrier()
        self._popen("mission", cli(*(["-vv"] if self.mission_verbose else []), "run", str(self.config), "--mavlink", f"udpin:127.0.0.1:{self.mav_port}",
                                   "--zenoh-connect", (self.mission_router or self.router).endpoint, "--pair", self.pair,
                                   "--speed", str(self.speed), "--log-dir", str(self.log_dir), *self._mode, *self.mission_args))
        wait_for(lambda: self.carrier_alive() and self.router.has(f"marsupial/{self.pair}/passenger/alive")
                 and udp_bound(self.mav_port) or self._died(), 30.0, "carrier and mission up")
        if self.before_vehicle is not None:
            self.before_vehicle(self)
        self.gcs = Probe()
        out = open(self.dir / "vehicle.out", "ab")
        err = open(self.dir / "vehicle.err", "ab")
        self._files += [out, err]
        vehicle, _ = spawn_process(["--mavlink", "udpin:127.0.0.1:0", "--target", f"udpout:127.0.0.1:{self.mav_port}",
                                    "--gcs", f"127.0.0.1:{self.gcs.port}", "--speed", str(self.speed), "--start-ned",
                                    "0,0,0", "--status-every", "0.5", *self._mode, *self.vehicle_args],
                                   stdout=out, stderr=err, env={**os.environ, "PYTHONUNBUFFERED": "1"})
        self.procs["vehicle"] = vehicle
        connect(self.gcs, timeout_s=10.0)

    def _died(self) -> bool:
        dead = {n: p.returncode for n, p in self.procs.items() if p.poll() is not None}
        if dead:
            raise AssertionError(f"process exited early: {dead}; mission stderr: {self.text('mission.err')}")
        return False

    def close(self) -> None:
        for name in ("mission", "vehicle", "carrier"):
            if name in self.procs:
                stop_process(self.procs[name])
        if self.gcs is not None:
            self.gcs.close()
        for f in self._files:
            f.close()

    # ---- observation -------------------------------------------------------------------------
    def text(self, name: str) -> str:
        path = self.dir / name
        return path.read_text(errors="replace") if path.exists() else ""

    def phases(self) -> list[str]:
        """Mission phases printed so far, in order."""
        return [line.split("] phase ", 1)[1].split()[0] for line in self.text("mission.out").splitlines()
                if "] phase " in line]

    def wait_phase(self, phase: str, timeout_s: float = 30.0) -> None:
        def seen() -> bool:
            if phase in self.phases():
                return True
            if self.procs["mission"].poll() is not None:
                raise AssertionError(f"mission exited ({self.procs['mission'].returncode}) before {phase}: "
                                     f"{self.phases()}\n{self.text('mission.err')}")
            return False
        wait_for(seen, timeout_s, f"mission phase {phase}")

    def wait_mission(self, timeout_s: float = 40.0) -> int:
        try:
            return self.procs["mission"].wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"mission still running in {self.phases()[-1:]} after {timeout_s} s") from None

    def vehicle_time_s(self) -> float:
        """The vehicle's simulated time [s] as the GCS link last heard it."""
        assert self.gcs is not None
        lp = self.gcs.latest("LOCAL_POSITION_NED")
        return 0.0 if lp is None else lp.time_boot_ms / 1000.0

    def vehicle(self) -> dict[str, Any]:
        """What the GCS link shows: mode, armed, landed state, position [m] NED, failsafe."""
        assert self.gcs is not None
        hb, lp, ess = (self.gcs.latest(k) for k in ("HEARTBEAT", "LOCAL_POSITION_NED", "EXTENDED_SYS_STATE"))
        return {"mode": px4.mode_name(hb.custom_mode), "armed": bool(hb.base_mode & px4.MAV_MODE_FLAG_SAFETY_ARMED),
                "critical": hb.system_status == px4.MAV_STATE_CRITICAL,
                "landed": None if ess is None else ess.landed_state,
                "ned": None if lp is None else (lp.x, lp.y, lp.z)}

    def modes_seen(self) -> list[str]:
        """Every mode the vehicle's HEARTBEATs showed on the GCS link, in order, without repeats."""
        assert self.gcs is not None
        out: list[str] = []
        for msg in self.gcs.messages("HEARTBEAT"):
            mode = px4.mode_name(msg.custom_mode)
            if not out or out[-1] != mode:
                out.append(mode)
        return out

    def record(self) -> list[dict[str, str]]:
        """The flight record's complete rows so far: read while the mission writes it, its last line
        may be a row half written (a CI run read one with an empty ``t_s``), which is left out."""
        text = (self.log_dir / "record.csv").read_text()
        if not text.endswith("\n"):
            text = text[:text.rfind("\n") + 1]
        return list(csv.DictReader(io.StringIO(text, newline="")))

    def summary(self) -> dict[str, Any]:
        return json.loads((self.log_dir / "summary.json").read_text())

    def tlog(self) -> list[tuple[float, Any]]:
        """The mission's flight.tlog as (mission clock [s], message): every packet it sent or
        received. The tlog stamps wall epoch + mission clock; the epoch is read off the mission's
        own setpoints, whose time_boot_ms is the mission clock when sent (to 1 ms)."""
        from mission.mavlink.env import mavlink

        data, i, stamped = (self.log_dir / "flight.tlog").read_bytes(), 0, []
        codec = mavlink.MAVLink(None)
        codec.robust_parsing = True
        while i + 8 < len(data):
            usec = int.from_bytes(data[i:i + 8], "big")
            size = 12 + data[i + 9] + (13 if data[i + 10] & 0x01 else 0)
            for msg in codec.parse_buffer(data[i + 8:i + 8 + size]) or []:
                stamped.append((usec, msg))
            i += 8 + size
        epochs = sorted(usec - m.time_boot_ms * 1000 for usec, m in stamped
                        if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED" and m.get_srcComponent() == 191)
        assert epochs, "no setpoint of the mission in its tlog"
        epoch = epochs[len(epochs) // 2]
        return [((usec - epoch) / 1e6, msg) for usec, msg in stamped]

    def carrier_summary(self) -> dict[str, Any]:
        """The carrier's own account (written when it stops): closest approach to the target [m]..."""
        return json.loads((self.dir / "carrier.json").read_text())

    def vehicle_counters(self) -> dict[str, int]:
        """The counters of the vehicle's last status line (``key=value`` pairs)."""
        lines = [line for line in self.text("vehicle.err").splitlines() if " rx=" in line]
        assert lines, "no vehicle status line"
        return {k: int(v.split("rej")[0].split("/")[0]) for k, v in
                (part.split("=", 1) for part in lines[-1].split() if "=" in part and not part.startswith(("t=", "ned=")))}


@contextlib.contextmanager
def flight(tmp_path: Path, name: str = "f", *, router: Router | None = None, start: bool = True,
           **kwargs: Any) -> Iterator[Flight]:
    """A :class:`Flight` in ``tmp_path/name`` with its own router unless one is given; every
    process it started is stopped (SIGTERM, then SIGKILL) on exit."""
    directory = tmp_path / name
    directory.mkdir(parents=True, exist_ok=True)
    own = router is None
    r = router or Router()
    f = Flight(dir=directory, router=r, **kwargs)
    try:
        if start:
            f.start()
        yield f
    finally:
        f.close()
        if own:
            r.close()


def assert_safe_end(f: Flight, *, modes: tuple[str, ...], timeout_s: float = 15.0) -> dict[str, Any]:
    """The vehicle ends safe: in one of ``modes`` armed in the air, or landed and disarmed on the
    ground; never disarmed in the air. ``"landed"`` in ``modes`` waits for the touchdown and the
    auto-disarm."""
    def ok() -> dict[str, Any] | None:
        v = f.vehicle()
        if "landed" in modes and not v["armed"] and v["landed"] == px4.LANDED_ON_GROUND:
            return v
        if v["mode"] in modes and v["armed"] and v["landed"] == px4.LANDED_IN_AIR:
            return v
        return None
    state = wait_for(ok, timeout_s, f"vehicle safe in {modes} (now {f.vehicle()})")
    return state


def assert_log_complete(f: Flight, phase: str, reason: str | None) -> dict[str, Any]:
    """record.csv has rows to the end (its last row is the final phase) and summary.json says
    how the mission ended."""
    rows = f.record()
    assert rows and rows[-1]["phase"] == phase, (rows[-1:] if rows else "no rows")
    summary = f.summary()
    assert summary["phase"] == phase and summary["reason"] == reason, summary
    assert summary["ticks"] == len(rows)
    assert (f.log_dir / "flight.tlog").stat().st_size > 0
    return summary
