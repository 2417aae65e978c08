"""The carrier's GNSS errors in ``marsupial carrier`` (sim/robots/truth.py through the entry point
``marsupial.world``): wrapped only when the configuration asks, seeded as the in-process
simulation's fixes, deterministic on the clock; its truth on a sim-only key that nothing of the
controller names; the marker's frames over the bus round-trip to the detector's pixels."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mission.bus.frames import decode_frame, encode_frame
from mission.carrier import cli as carrier_cli
from mission.carrier.backends.sim import SimRobot
from mission.carrier.controller import frames_disagree_m
from mission.config.schema import load_config, with_overrides
from mission.errors import ConfigError
from mission.time.clock import ManualClock
from mission.vision.camera import Frame
from sim.gnss import CarrierGnss, ErringCarrier
from sim.robots.truth import truth_key
from tests.conftest import CONFIGS

ROOT = Path(__file__).resolve().parents[3]
RELNAV = CONFIGS / "relnav.toml"


def test_nothing_of_the_controller_names_the_truth_key():
    """The truth is the world's: no module under mission/ names its key (or builds it), so neither
    the passenger nor the carrier's controller can subscribe to it; the simulator defines it."""
    assert truth_key("pair0") == "marsupial/pair0/sim/carrier_truth"
    offenders = [str(p.relative_to(ROOT)) for p in sorted((ROOT / "mission").rglob("*.py"))
                 if "carrier_truth" in p.read_text() or "truth_key" in p.read_text()]
    assert offenders == []
    assert "carrier_truth" in (ROOT / "sim" / "robots" / "truth.py").read_text()  # the check can see it


def test_the_carrier_wraps_its_backend_only_when_the_world_asks(monkeypatch):
    cfg = load_config(RELNAV)
    clock = ManualClock()
    plain = with_overrides(cfg, {"world.carrier_gnss.enabled": False})
    robot = SimRobot(plain, clock)
    assert carrier_cli.with_world(plain, robot, clock, None) is robot
    monkeypatch.setattr(carrier_cli, "entry_points", lambda group: {})  # no simulator installed
    with pytest.raises(ConfigError, match=r"world\.carrier_gnss\.enabled.*marsupial\.world"):
        carrier_cli.with_world(cfg, SimRobot(cfg, clock), clock, None)


def _fixes(cfg, steps: int) -> list[tuple[float, list[float]]]:
    """The erring own states of the built-in robot standing at the start, on a manual clock."""
    clock = ManualClock()
    carrier = ErringCarrier(SimRobot(cfg, clock), cfg.world.carrier_gnss)
    out = []
    for _ in range(steps):
        clock.advance(1.0 / 30)
        carrier.advance(1.0 / 30)
        s = carrier.own_state()
        if s is not None:
            out.append((s.t_s, s.position_ned_m.round(9).tolist()))
    return out


def test_the_carriers_errors_are_seeded_as_the_simulations_and_deterministic():
    """Two runs on the same clock give the same fixes to the bit; the bias is the one the
    in-process simulation's CarrierGnss draws from world.carrier_gnss.seed; another seed, another."""
    cfg = load_config(RELNAV)
    a, b = _fixes(cfg, 300), _fixes(cfg, 300)
    assert a == b and len(a) > 250
    assert np.allclose(CarrierGnss(cfg.world.carrier_gnss).bias.value_ned_m,
                       CarrierGnss(cfg.world.carrier_gnss).bias.value_ned_m)
    other = with_overrides(cfg, {"world.carrier_gnss.seed": cfg.world.carrier_gnss.seed + 1})
    assert _fixes(other, 300) != a
    # the fix is the truth (the start, standing) off by the bias and noise: metres, not nothing
    assert all(0.3 < np.hypot(*p[:2]) < 8.0 for _, p in a)


def test_with_relnav_the_carrier_allows_the_frames_disagreement_on_the_dock_check():
    cfg = load_config(RELNAV)
    assert frames_disagree_m(with_overrides(cfg, {"relnav.enabled": False})) == 0.0
    r = cfg.relnav
    assert frames_disagree_m(cfg) == pytest.approx(3.0 * r.bias_sigma_m * np.sqrt(2.0 + r.vertical_factor ** 2))


def test_a_camera_frame_round_trips_through_the_bus_encoding():
    image = (np.arange(48 * 64) % 251).astype(np.uint8).reshape(48, 64)
    q = np.array([0.9, 0.0, 0.0, 0.43588989])
    frame, got_q = decode_frame(encode_frame(Frame(image, 12.34), q))
    assert frame.capture_t_s == 12.34 and np.array_equal(frame.image, image) and np.allclose(got_q, q)
    with pytest.raises(ValueError):
        decode_frame(encode_frame(Frame(image, 1.0), q)[:-1])  # a pixel short


def test_a_time_mark_says_the_stream_passed_a_time_without_a_frame():
    from mission.bus.frames import encode_mark

    frame, q = decode_frame(encode_mark(3.5))
    assert frame.capture_t_s == 3.5 and frame.image.size == 0 and np.allclose(q, [1.0, 0.0, 0.0, 0.0])
