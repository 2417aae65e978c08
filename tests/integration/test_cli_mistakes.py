"""A new user's mistakes, through the real command line: a message that says what happened and
what to do, a documented exit code, never a traceback."""
from __future__ import annotations

import os
import socket
import subprocess
import sys

from tests.conftest import CONFIGS, ROOT, free_port


def _cli(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "mission.cli", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT, env=env)


def test_second_mock_vehicle_names_the_port_and_its_holder():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        out = _cli("mock-vehicle", "--mavlink", f"udpin:127.0.0.1:{port}", "--target", "udpout:127.0.0.1:9")
    assert out.returncode == 6, out.stderr
    assert "Traceback" not in out.stderr
    assert f"UDP port 127.0.0.1:{port} is already in use, held by process {os.getpid()}" in out.stderr


def test_run_with_a_taken_mavlink_port_names_it():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        out = _cli("run", str(CONFIGS / "demo.toml"), "--mavlink", f"udpin:127.0.0.1:{port}",
                   "--zenoh-listen", "tcp/127.0.0.1:0")
    assert out.returncode == 6 and "Traceback" not in out.stderr
    assert f"127.0.0.1:{port} is already in use, held by process {os.getpid()}" in out.stderr


def test_run_without_a_vehicle_says_what_it_waits_for_and_what_to_do(tmp_path):
    cfg = tmp_path / "short.toml"
    text = (CONFIGS / "demo.toml").read_text().replace("connect_timeout_s = 20.0", "connect_timeout_s = 1.5")
    assert "connect_timeout_s = 1.5" in text
    cfg.write_text(text)
    mav = free_port(socket.SOCK_DGRAM)
    out = _cli("run", str(cfg), "--mavlink", f"udpin:127.0.0.1:{mav}", "--zenoh-listen", "tcp/127.0.0.1:0",
               "--pair", "lonely", "--log-dir", str(tmp_path / "log"))
    assert out.returncode == 3, out.stdout + out.stderr
    assert "Traceback" not in out.stderr and "Warning" not in out.stderr
    assert f"vehicle on MAVLink udpin:127.0.0.1:{mav}" in out.stdout
    assert f"waiting for the vehicle (no HEARTBEAT yet on udpin:127.0.0.1:{mav}) and the carrier " \
           "(no state yet on marsupial/lonely/carrier/state); giving up in" in out.stdout
    assert "mission.connect_timeout_s = 1.5 s" in out.stdout
    assert "start `marsupial mock-vehicle`" in out.stderr
    assert "separation_time_s" not in out.stdout  # no table of None for a mission that never rode


def test_run_live_with_a_bad_address_a_taken_port_or_off_loopback_says_so(tmp_path):
    """--live: a malformed address is exit 2 before anything is written; a taken port is named
    with its holder (exit 6); an address off loopback flies with a warning."""
    demo = str(CONFIGS / "demo.toml")
    out = _cli("run", demo, "--live", "127.0.0.1:http", "--log-dir", str(tmp_path / "a"))
    assert out.returncode == 2 and "Traceback" not in out.stderr and "--live" in out.stderr
    assert not (tmp_path / "a").exists()
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        out = _cli("run", demo, "--live", f"127.0.0.1:{port}", "--mavlink", f"udpin:127.0.0.1:{free_port(socket.SOCK_DGRAM)}",
                   "--zenoh-listen", "tcp/127.0.0.1:0", "--log-dir", str(tmp_path / "b"))
    assert out.returncode == 6 and "Traceback" not in out.stderr, out.stderr
    assert f"Foxglove live view ws://127.0.0.1:{port}" in out.stderr and f"held by process {os.getpid()}" in out.stderr
    cfg = tmp_path / "short.toml"
    cfg.write_text((CONFIGS / "demo.toml").read_text().replace("connect_timeout_s = 20.0", "connect_timeout_s = 1.0"))
    out = _cli("run", str(cfg), "--live", f"0.0.0.0:{free_port()}", "--mavlink", f"udpin:127.0.0.1:{free_port(socket.SOCK_DGRAM)}",
               "--zenoh-listen", "tcp/127.0.0.1:0", "--log-dir", str(tmp_path / "c"))
    assert out.returncode == 3 and "Traceback" not in out.stderr, out.stderr
    assert "warning: the live view binds 0.0.0.0, not loopback" in out.stderr
    assert "live view: ws://0.0.0.0:" in out.stdout and (tmp_path / "c" / "flight.mcap").stat().st_size > 0


def test_plot_of_a_folder_without_logs_says_which_folder_to_give(tmp_path):
    out = _cli("plot", str(tmp_path))
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert "holds no flight log" in out.stderr and "logs/demo/pair0" in out.stderr


def test_carrier_with_a_taken_zenoh_port_names_it_and_says_who_it_is():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        out = _cli("carrier", str(CONFIGS / "demo.toml"), "--zenoh-listen", f"tcp/127.0.0.1:{port}", "--pair", "busy")
    assert out.returncode == 6 and "Traceback" not in out.stderr
    first = out.stderr.splitlines()[0]  # the start-up line: pair, key, endpoint, mode
    assert first.startswith("carrier busy: ") and "marsupial/busy/carrier/state" in first
    assert f"Zenoh peer, listen tcp/127.0.0.1:{port}" in first and "mode stop" in first
    assert f"Zenoh listen endpoint tcp/127.0.0.1:{port}: TCP port 127.0.0.1:{port} is already in use, " \
           f"held by process {os.getpid()}" in out.stderr


def test_ros2_robot_in_lockstep_on_ros2dds_keys_says_why_not():
    out = _cli("ros2-robot", "--key-form", "ros2dds", "--lockstep", timeout=30)
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert "lockstep needs --key-form rmw_zenoh" in out.stderr
