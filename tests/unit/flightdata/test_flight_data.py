"""flight.mcap as a sink of the flight record (no sockets): the same rows as record.csv, read back
by ``marsupial plot``; the live address rules."""
from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from mission.cli.run import plot
from mission.config.recovery import RecoverySection
from mission.core.docking import holdoff_point
from mission.core.setpoint import Setpoint
from mission.errors import ConfigError
from mission.flightdata.mission_log import MissionLog, bc_circle
from mission.flightdata.read import read_messages
from mission.flightdata.topics import CAMERA_CHANNELS, CARRIER_CHANNELS, MISSION_CHANNELS, RELNAV_CHANNELS, topics
from mission.flightdata.writer import LiveAddress, is_loopback, parse_live
from mission.model import docking_geometry
from mission.record.recorder import FlightRecorder
from mission.record.table import TickRow, read_record

INFO = {"target_ned_m": [20.0, 0.0, -5.0], "obstacles": [{"center": [10.0, 3.0, -2.0], "radius": 1.0}], "bc_m": 8.0,
        "carrier_start_ned_m": [0.0, 0.0, 0.0], "dock_offset_ned_m": [0, 0, -1.5], "dock_tolerance_m": 0.5,
        "arrival_radius_m": 0.5, "pair": "pairX"}


def _fly(directory, ticks: int = 150) -> None:
    """A made-up flight of ``ticks`` rows at 10 Hz through a recorder with a MissionLog sink."""
    log = MissionLog(directory / "flight.mcap", INFO, pair="pairX", clock={"clock": "mission"})
    rec = FlightRecorder(directory, INFO, [log])
    rec.set_counters(lambda: {"carrier_feed": {"received": 3, "accepted": 3, "dropped": {}}, "link": {"rx_messages": 9}})
    z = np.zeros(3)
    anchor = None
    phase = None
    for k in range(ticks):
        new = "JOIN" if k < 10 else ("RIDING" if k < 100 else "NAVIGATING")
        x_c = np.array([k * 0.1, 0.0, 0.0])
        dock = x_c + [0, 0, -1.5]
        x_p = dock if k < 100 else dock + [(k - 100) * 0.2, 0, -0.05 * (k - 100)]
        if k == 100:
            anchor = dock.copy()
        events = (f"phase {new}",) if new != phase else ()
        phase = new
        rec.record_row(TickRow(k * 0.1, new, x_p, z, x_c, z, dock, x_p, 0.5 if k >= 10 else float("nan"), z,
                               np.array([0.3, 0.0, 0.0]), Setpoint.triple(x_p, np.array([0.2, 0.0, 0.0]), z),
                               k % 7 == 0, 0.01, "OFFBOARD", True, u_ref=z, anchor=anchor, events=events))
    rec.close({"phase": "NAVIGATING"}, {"separation_time_s": 10.0, "anchor_ned_m": anchor.tolist()})


def test_the_mcap_holds_the_csv_rows_and_the_foxglove_channels(tmp_path):
    _fly(tmp_path)
    csv_rec, mcap_rec = read_record(tmp_path), read_record(tmp_path / "flight.mcap")
    assert csv_rec.cols.keys() == mcap_rec.cols.keys()
    for name, values in csv_rec.cols.items():
        assert np.array_equal(values, mcap_rec.cols[name], equal_nan=True), name
    assert (csv_rec.phase == mcap_rec.phase).all()
    assert mcap_rec.info["anchor_ned_m"] == [10.0, 0.0, -1.5] and mcap_rec.info["target_ned_m"] == INFO["target_ned_m"]
    with open(tmp_path / "flight.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None
        assert sorted(c.topic for c in summary.channels.values()) == sorted(topics("pairX").values())
        logs = [m.message for *_, m in reader.iter_decoded_messages(topics=["/pairX/log"])]
        dock = [m for *_, m in reader.iter_decoded_messages(topics=["/pairX/tf/dock"])][0]
    assert logs == ["phase JOIN", "phase RIDING", "phase NAVIGATING"]
    assert (dock.parent_frame_id, dock.child_frame_id, dock.translation.z) == ("map_ned", "pairX/dock", -1.5)
    content = read_messages(tmp_path / "flight.mcap")
    assert content.complete
    distances = [json.loads(d) for t, s, _, d in content.messages if t == "/pairX/distances"]
    assert distances[0]["P"] is None and distances[-1]["e_pc_m"] == pytest.approx(np.hypot(49 * 0.2, 49 * 0.05))
    safety = [json.loads(d) for t, s, _, d in content.messages if t == "/pairX/safety"]
    assert safety[-1]["acted_ticks"] == sum(1 for k in range(150) if k % 7 == 0)
    setpoints = [json.loads(d) for t, s, _, d in content.messages if t == "/pairX/setpoint"]
    assert setpoints[0]["kind"] == "full" and setpoints[0]["velocity"] == {"n": 0.2, "e": 0.0, "d": 0.0}
    assert setpoints[0]["position"] == {"n": 0.0, "e": 0.0, "d": -1.5} and setpoints[0]["yaw_rad"] is None
    feed = [json.loads(d) for t, s, _, d in content.messages if t == "/pairX/carrier_feed"]
    assert len(feed) == 15 and feed[0]["received"] == 3  # once a second of mission clock
    assert len(MISSION_CHANNELS) == len(topics("pairX")) == 14


def test_plot_reads_the_mcap_as_it_reads_the_csv(tmp_path):
    _fly(tmp_path)
    (tmp_path / "record.csv").rename(tmp_path / "record.csv.bak")  # the directory's MCAP, then the file itself
    for target, out in ((tmp_path, tmp_path / "dir.png"), (tmp_path / "flight.mcap", tmp_path / "file.png")):
        result = CliRunner().invoke(plot, [str(target), "--out", str(out)], standalone_mode=False)
        assert result.exception is None, result.output
        assert out.stat().st_size > 20_000
    result = CliRunner().invoke(plot, [str(tmp_path / "mission.json")], standalone_mode=False)
    assert isinstance(result.exception, ConfigError) and "not an MCAP" in str(result.exception)
    result = CliRunner().invoke(plot, [str(tmp_path), "--panels"], standalone_mode=False)  # the layout's panels
    assert result.exception is None, result.output
    assert (tmp_path / "flight-panels.png").stat().st_size > 50_000


def test_the_bc_circle_lies_in_the_docks_plane_b_c_from_the_target():
    pts = bc_circle(INFO)
    assert np.allclose(pts[:, 2], -1.5)
    assert np.allclose(np.linalg.norm(pts - np.asarray(INFO["target_ned_m"]), axis=1), 8.0)


@pytest.mark.parametrize("text,address", [
    ("127.0.0.1:8765", LiveAddress("127.0.0.1", 8765)), ("8765", LiveAddress("127.0.0.1", 8765)),
    (":0", LiveAddress("127.0.0.1", 0)), ("[::1]:9000", LiveAddress("::1", 9000)),
    ("0.0.0.0:8765", LiveAddress("0.0.0.0", 8765)), ("localhost:1", LiveAddress("localhost", 1))])
def test_live_addresses(text, address):
    assert parse_live(text) == address


@pytest.mark.parametrize("text", ["nope", "127.0.0.1:http", "127.0.0.1:70000", "1.2.3.4:-1"])
def test_a_bad_live_address_names_the_option(text):
    with pytest.raises(ConfigError) as err:
        parse_live(text)
    assert err.value.field == "--live"


def test_loopback_hosts():
    assert is_loopback("127.0.0.1") and is_loopback("127.5.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.2") and not is_loopback("example.org")
    assert LiveAddress("::1", 8765).url == "ws://[::1]:8765"


def test_the_shipped_layout_is_the_generated_one_and_names_only_real_topics_and_fields():
    """configs/foxglove/marsupial.json = mission.flightdata.layout (regenerate with
    ``python -m mission.flightdata.layout``); each message path in it is a pair0 topic with a
    field its schema has."""
    from mission.flightdata.layout import LAYOUT_FILE, layout_text
    from mission.flightdata.topics import JSON_SCHEMAS

    assert LAYOUT_FILE.read_text() == layout_text()
    text = LAYOUT_FILE.read_text()
    schema_of = {topic: schema for (_, name, schema), topic in zip(MISSION_CHANNELS, topics("pair0").values())}
    schema_of |= {topic: schema for (_, name, schema), topic in zip(CARRIER_CHANNELS,
                                                                    topics("pair0", CARRIER_CHANNELS).values())}
    schema_of |= {topic: schema for (_, name, schema), topic in zip(CAMERA_CHANNELS,
                                                                    topics("pair0", CAMERA_CHANNELS).values())}
    schema_of |= {topic: schema for (_, name, schema), topic in zip(RELNAV_CHANNELS,
                                                                    topics("pair0", RELNAV_CHANNELS).values())}
    paths = _paths(json.loads(text))
    assert len(paths) >= 12
    for path in paths:
        topic, _, field = path.partition(".")
        assert topic in schema_of, path
        if field:
            assert field.split(".")[0] in JSON_SCHEMAS[schema_of[topic]]["properties"], path
    assert {"/pair0/scene", "/pair0/log", "/pair0/distances.e_pc_m", "/pair0/command.safe.n",
            "/pair0/carrier/status.mode", "/pair0/carrier/status.target_distance_m", "/pair0/camera/image",
            "/pair0/camera/calibration", "/pair0/camera/detections", "/pair0/relnav.position_sigma_m"} <= set(paths)


def _paths(node) -> list[str]:
    """Every message path (series values, the log's topic, topic settings' keys) in a layout."""
    out = []
    if isinstance(node, dict):
        for key, value in node.items():
            if key in ("value", "topicToRender", "imageTopic", "calibrationTopic") and isinstance(value, str):
                out.append(value)
            elif key in ("topics", "annotations") and isinstance(value, dict):
                out.extend(value)
            else:
                out.extend(_paths(value))
    elif isinstance(node, list):
        for item in node:
            out.extend(_paths(item))
    return out


def test_a_recovery_draws_its_holdoff_point_and_glide_path_in_the_docks_frame(tmp_path):
    """While a recovery runs (the row has the carrier's course) the scene holds the holdoff point
    and the glide path, relative to the dock point, turned with the course; they live 1.5 s."""
    g = docking_geometry(RecoverySection())
    log = MissionLog(tmp_path / "flight.mcap", INFO, pair="pairX", clock={"clock": "mission"}, docking=g)
    rec = FlightRecorder(tmp_path, INFO, [log])
    z = np.zeros(3)
    east = np.array([0.0, 1.0, 0.0])
    for k in range(30):
        x_c = np.array([0.0, k * 0.1, 0.0])
        dock = x_c + [0, 0, -1.5]
        rec.record_row(TickRow(k * 0.1, "HOLDOFF" if k >= 10 else "ARRIVED", dock + [0, -2, -2], z, x_c, z, dock,
                               dock, float("nan"), None, None, Setpoint(z), False, 0.01, "OFFBOARD", True,
                               course=east if k >= 10 else None))
    rec.close({"phase": "HOLD"}, {})
    with open(tmp_path / "flight.mcap", "rb") as f:
        scenes = [(msg.log_time, m) for _, _, msg, m in make_reader(f, decoder_factories=[DecoderFactory()])
                  .iter_decoded_messages(topics=["/pairX/scene"])]
    before = [m for t, m in scenes if t < 1.0e9]
    during = [m for t, m in scenes if t >= 1.0e9]
    assert before and not {"holdoff", "glide_path"} & {e.id for m in before for e in m.entities}
    assert [t for t, _ in scenes if t >= 1.0e9][0] == 1_000_000_000  # drawn again when the recovery began
    holdoff = next(e for e in during[0].entities if e.id == "holdoff")
    glide = next(e for e in during[0].entities if e.id == "glide_path")
    assert holdoff.frame_id == glide.frame_id == "pairX/dock" and holdoff.frame_locked
    assert holdoff.lifetime.seconds == 1 and holdoff.lifetime.nanos == 500_000_000
    h = holdoff_point(z, east, g)
    p = holdoff.spheres[0].pose.position
    assert (p.x, p.y, p.z) == pytest.approx(tuple(h))
    assert h[1] == pytest.approx(-g.holdoff_distance_m) and h[2] < 0  # behind (course east) and above
    points = [c for q in glide.lines[0].points for c in (q.x, q.y, q.z)]
    assert points == pytest.approx([*h, 0, 0, -g.decision_height_m, 0, 0, 0])  # H -> gate -> dock


def _decoded(path, topic: str) -> list:
    with open(path, "rb") as f:
        return [(msg.log_time, m) for _, _, msg, m in make_reader(f, decoder_factories=[DecoderFactory()])
                .iter_decoded_messages(topics=[topic])]


def _carrier_step(t_s: float, yaw_rad: float | None) -> Any:
    from mission.carrier.controller import CarrierStep, OwnState
    from mission.carrier.tracking import Tracked

    state = OwnState(t_s, np.array([1.0, 2.0, 0.0]), np.zeros(3), yaw_rad)
    return CarrierStep(t_s, "approaching", None, state, Tracked(0.0, 0.0, 0.0, np.zeros(2), np.zeros(2)), np.zeros(2), 0, None)


def test_a_flight_and_its_carrier_log_epoch_time_and_line_up_in_real_time(tmp_path):
    """Two real-time processes, their clocks started 2.5 s apart: what each logs at one wall
    instant carries one log time (epoch ns, the wall clock's) within 0.1 s; readers still get
    mission-clock seconds back."""
    import time

    from mission.flightdata.carrier_log import CarrierLog
    from mission.flightdata.read import log_lines
    from mission.flightdata.writer import clock_metadata
    from mission.time.clock import ScaledClock

    mission_clock, carrier_clock = ScaledClock(1.0, start_s=2.5), ScaledClock(1.0)  # the mission started first
    flight = MissionLog(tmp_path / "flight.mcap", INFO, pair="pairX", clock=clock_metadata(mission_clock, "", ""))
    carrier = CarrierLog(tmp_path / "carrier.mcap", pair="pairX", target=INFO["target_ned_m"],
                         clock=clock_metadata(carrier_clock, "", ""))
    wall = time.time_ns()
    t_m, t_c = mission_clock.now(), carrier_clock.now()
    z = np.zeros(3)
    flight.tick(TickRow(t_m, "RIDING", z, z, z, z, z, z, 0.5, z, z, None, False, 0.01, "OFFBOARD", True,
                        events=("phase RIDING",), yaw_c=0.3))
    carrier.step(_carrier_step(t_c, 0.3))
    flight.close({}, {})
    carrier.close()
    (t_flight, _), = _decoded(tmp_path / "flight.mcap", "/pairX/tf/carrier")
    (t_carrier, _), = _decoded(tmp_path / "carrier.mcap", "/pairX/carrier/tf")
    assert abs(t_flight - t_carrier) < 0.1e9 and abs(t_flight - wall) < 0.1e9
    assert abs(t_m - t_c - 2.5) < 0.1  # their own clocks differ by the 2.5 s
    content = read_messages(tmp_path / "flight.mcap")
    assert content.epoch_ns > 1.5e18 and log_lines(content, "/pairX/log")[0][0] == pytest.approx(t_m, abs=1e-6)


def test_lockstep_processes_share_the_demos_epoch():
    from mission.flightdata.writer import clock_metadata, log_epoch_ns
    from mission.time.clock import LockstepClock

    clock = LockstepClock(speed=1.0, name="t", creator_runs=False)
    try:
        assert clock_metadata(clock, "", "", 1_700_000_000_000_000_000)["epoch_ns"] == "1700000000000000000"
        assert log_epoch_ns(clock, 42) == 42
    finally:
        clock.close()


def test_transforms_carry_heading_in_ros_frames(tmp_path):
    """map -> map_ned (NED under ENU), a robot's base_link_frd turned by its heading about down,
    base_link (FLU) half a turn about forward under it; the carrier's own log too."""
    import math

    from mission.flightdata.carrier_log import CarrierLog

    log = MissionLog(tmp_path / "flight.mcap", INFO, pair="pairX", clock={"clock": "mission"})
    z = np.zeros(3)
    log.tick(TickRow(0.0, "RIDING", z, z, z, z, z, z, 0.5, z, z, None, False, 0.01, "OFFBOARD", True, yaw_c=1.0))
    log.close({}, {})
    (_, carrier), = _decoded(tmp_path / "flight.mcap", "/pairX/tf/carrier")
    (_, passenger), = _decoded(tmp_path / "flight.mcap", "/pairX/tf/passenger")
    assert (carrier.parent_frame_id, carrier.child_frame_id) == ("map_ned", "pairX/carrier/base_link_frd")
    q = carrier.rotation
    assert (q.x, q.y, q.z, q.w) == pytest.approx((0.0, 0.0, math.sin(0.5), math.cos(0.5)))
    assert passenger.rotation.w == 1.0  # the passenger's heading is not known: no rotation
    fixed = {(m.parent_frame_id, m.child_frame_id): m.rotation for _, m in _decoded(tmp_path / "flight.mcap", "/pairX/tf/world")}
    assert fixed[("map", "map_ned")].x == pytest.approx(math.sqrt(0.5))
    assert fixed[("pairX/carrier/base_link_frd", "pairX/carrier/base_link")].x == 1.0
    own = CarrierLog(tmp_path / "carrier.mcap", pair="pairX", target=INFO["target_ned_m"], clock={"clock": "mission"})
    for k, yaw in enumerate((0.0, -2.0)):
        own.step(_carrier_step(k * 0.1, yaw))
    own.close()
    tfs = [m for _, m in _decoded(tmp_path / "carrier.mcap", "/pairX/carrier/tf")]
    assert tfs[-1].child_frame_id == "pairX/carrier_own/base_link_frd"
    assert (tfs[0].rotation.z, tfs[-1].rotation.z) == pytest.approx((0.0, math.sin(-1.0)))
