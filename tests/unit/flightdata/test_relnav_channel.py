"""The relative estimate in ``flight.mcap`` (``/<pair>/relnav``): a mission loop flown on the fake
world with ``[relnav]`` on and a marker feed, its MCAP read back (mission.flightdata.read); and a
flight without ``[relnav]``, whose MCAP has no such channel. Manual clock, no sockets."""
from __future__ import annotations

import json
import threading

import numpy as np
import pytest
from mcap.reader import make_reader

from mission.config.schema import load_config, with_overrides
from mission.controller import MissionController
from mission.flightdata.mission_log import MissionLog, relnav_message
from mission.flightdata.read import RECORD_SCHEMA, read_messages
from mission.flightdata.topics import JSON_SCHEMAS, RELNAV_CHANNELS, topics
from mission.phases.types import RelativeView
from mission.record.info import mission_info
from mission.record.recorder import FlightRecorder
from mission.time.clock import ManualClock
from tests.conftest import CONFIGS
from tests.support.fake_vehicle import FakeWorld, TrueMarker

PAIR = "pairR"
TOPIC = topics(PAIR, RELNAV_CHANNELS)["relnav"]
UNTIL_S = 8.0  # [s] of mission clock flown (JOIN, the ride: the marker in view all along)


def fly(tmp_path, relnav: bool):
    """The demo mission (pair ``PAIR``), ``[relnav]`` on or off, with a perfect marker feed and a
    recorder with a MissionLog sink, stopped after ``UNTIL_S``; returns the controller, the MCAP's
    path and the truth (carrier minus vehicle [m]) by tick time."""
    cfg = with_overrides(load_config(CONFIGS / "demo.toml"), {"relnav.enabled": relnav, "zenoh.pair": PAIR})
    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(cfg.scenario.target, dtype=float))
    dock_offset = np.asarray(cfg.mission.dock_offset_ned_m, dtype=float)
    info = mission_info(cfg)
    path = tmp_path / "flight.mcap"
    recorder = FlightRecorder(tmp_path, info, [MissionLog(path, info, pair=PAIR, clock={"clock": "mission"})])
    truth: dict[float, np.ndarray] = {}
    stop = threading.Event()

    def on_tick(report) -> None:
        truth[round(report.t_s, 6)] = world.carrier_ned_m - world.vehicle_ned_m
        if report.t_s > UNTIL_S:
            stop.set()

    controller = MissionController(cfg, world, world.feed, clock, recorder=recorder, command_thread=False, stop=stop,
                                   sources=[TrueMarker(world, dock_offset)], on_tick=on_tick)
    controller.run()
    return controller, path, truth


def channel_topics(path) -> set[str]:
    """Every channel the MCAP declares (its summary's), messages or not."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return {c.topic for c in summary.channels.values()}


def matrix(values) -> np.ndarray:
    assert values is not None and len(values) == 9
    return np.asarray(values, dtype=float).reshape(3, 3)


def test_a_relnav_flight_logs_every_ticks_estimate_with_its_covariance(tmp_path):
    controller, path, truth = fly(tmp_path, relnav=True)
    content = read_messages(path)
    rows = [(t, json.loads(d)) for topic, _, t, d in content.messages if topic == TOPIC]
    ticks = [t for topic, schema, t, _ in content.messages if schema == RECORD_SCHEMA]
    assert {s for topic, s, _, _ in content.messages if topic == TOPIC} == {"marsupial.RelativeEstimate"}
    # one message per tick from the first estimate on (the view exists once the vehicle's first sample has come)
    assert len(rows) > 300 and [t for t, _ in rows] == ticks[len(ticks) - len(rows):], (len(rows), len(ticks))
    fields = set(JSON_SCHEMAS["marsupial.RelativeEstimate"]["properties"])
    for t_ns, m in rows:
        assert set(m) == fields
        p = matrix(m["position_covariance_m2"])
        for key in ("position_covariance_m2", "velocity_covariance_m2_s2", "bias_covariance_m2"):
            c = matrix(m[key])
            assert np.all(np.isfinite(c)) and np.allclose(c, c.T, rtol=0, atol=1e-12), (key, c)
            assert np.linalg.eigvalsh(c).min() >= -1e-12, (key, np.linalg.eigvalsh(c))
        assert np.sqrt(np.linalg.eigvalsh(p).max()) == pytest.approx(m["position_sigma_m"], rel=1e-9)
        sigma = m["position_sigma"]
        assert [sigma[a] for a in "ned"] == pytest.approx(np.sqrt(np.diag(p)).tolist(), rel=1e-12)
        assert m["converged"] == (m["position_sigma_m"] < controller.cfg.relnav.converged_sigma_m)
        for key in ("position", "velocity", "carrier_position", "carrier_velocity", "bias", "pending"):
            assert m[key] is not None and all(np.isfinite(m[key][a]) for a in "ned"), (key, m[key])
        assert np.isfinite(m["sample_t_s"])
    first, last = rows[0][1], rows[-1][1]
    assert not first["converged"] and first["position_sigma_m"] > 0.5  # the prior: nothing fused yet
    assert last["converged"] and last["since_marker_s"] is not None and last["since_marker_s"] < 0.1
    assert last["fused"]["marker"] > 300 and last["fused"]["gnss_position"] > 0 and last["rejected"]["marker"] == 0
    # the estimate is deck minus vehicle (the carrier's reference point minus the vehicle's): the truth's sign
    t_last = round((rows[-1][0] - content.epoch_ns) / 1e9, 6)
    error = np.array([last["position"][a] for a in "ned"]) - truth[min(truth, key=lambda k: abs(k - t_last))]
    assert np.linalg.norm(error) < 0.1, error
    # the last message is the estimator's last estimate, to the bit
    final = controller.step.relative.estimator.estimate()
    assert np.array_equal(matrix(last["position_covariance_m2"]), final.covariance[:3, :3])
    assert np.array_equal(matrix(last["bias_covariance_m2"]), final.covariance[6:9, 6:9])
    assert last["position_sigma_m"] == final.position_sigma_m
    assert last["fused"] == final.counts.fused and last["resets"] == final.counts.resets


def test_the_logged_inputs_replay_the_flights_estimator_to_the_bit(tmp_path):
    """Every input the step handed the estimator is logged, in order, exactly: a fresh estimator
    fed them gives every tick's logged estimate and the flight's last one, bit for bit."""
    from mission.flightdata.relnav_inputs import KINDS, input_from_message, input_message
    from mission.passenger.relative import hand
    from mission.relnav.estimator import RelativeEstimator

    controller, path, _ = fly(tmp_path, relnav=True)
    content = read_messages(path)
    inputs_topic = topics(PAIR, RELNAV_CHANNELS)["relnav_inputs"]
    logged = [json.loads(d) for topic, _, _, d in content.messages if topic == inputs_topic]
    estimates = [json.loads(d) for topic, _, _, d in content.messages if topic == TOPIC]
    assert [m["seq"] for m in logged] == list(range(len(logged)))
    kinds = {k: sum(m["kind"] == k for m in logged) for k in KINDS}
    assert kinds["own"] == len(estimates) and kinds["marker"] > 300 and kinds["carrier"] > 0, kinds
    fields = set(JSON_SCHEMAS["marsupial.RelativeInput"]["properties"])
    assert all(set(m) <= fields for m in logged)
    est = RelativeEstimator(controller.cfg.relnav.params())
    replayed = []
    for m in logged:
        item = input_from_message(m)
        assert input_message(item, m["seq"]) == m  # the message round-trips
        e = hand(est, item)
        if e is not None:
            replayed.append(e)
    assert len(replayed) == len(estimates)
    for e, m in zip(replayed, estimates):
        assert e.t_s == m["sample_t_s"]
        assert [m["carrier_velocity"][a] for a in "ned"] == e.carrier_velocity_ned_m_s.tolist()
        assert [m["position"][a] for a in "ned"] == pytest.approx(e.position_ned_m.tolist(), rel=0, abs=0)
    final = controller.step.relative.estimator.estimate()
    assert np.array_equal(est.estimate().covariance, final.covariance) and est.counts() == final.counts
    with pytest.raises(ValueError, match="kind 'gps'"):
        input_from_message({"kind": "gps", "t_s": 0.0})


def test_a_flight_without_relnav_has_no_relnav_channel(tmp_path):
    controller, path, _ = fly(tmp_path, relnav=False)
    assert controller.step.relative is None
    names = channel_topics(path)
    assert topics(PAIR)["record"] in names  # the file is whole and has the mission's channels
    assert TOPIC not in names
    assert not [m for m in read_messages(path).messages if m[0] == TOPIC]


def test_the_estimates_covariance_is_a_read_only_copy():
    from mission.relnav.estimator import RelativeEstimator
    from mission.relnav.inputs import OwnSample

    cfg = with_overrides(load_config(CONFIGS / "demo.toml"), {"relnav.enabled": True})
    est = RelativeEstimator(cfg.relnav.params())
    e = est.tick(OwnSample(0.0, np.zeros(3), np.zeros(3)))
    with pytest.raises(ValueError):
        e.covariance[0, 0] = 0.0
    assert est.estimate().covariance[0, 0] > 0.0


def test_a_view_without_the_estimate_logs_its_own_fields_and_nulls():
    view = RelativeView(np.array([1.0, 2.0, 3.0]), np.zeros(3), np.zeros(3), 0.05, True, float("inf"))
    m = relnav_message(view)
    assert m["position"] == {"n": 1.0, "e": 2.0, "d": 3.0} and m["position_sigma_m"] == 0.05
    assert m["since_marker_s"] is None and m["position_covariance_m2"] is None and m["fused"] is None
    assert set(m) == set(JSON_SCHEMAS["marsupial.RelativeEstimate"]["properties"])
