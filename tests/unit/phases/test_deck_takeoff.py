"""The take-off from the deck on PX4's estimate (pure, synthetic observations): the seated
vehicle's estimate misplaces it on the deck by decimetres (PX4 SITL's errors: 0.15 m per axis,
0.3 m vertically), and neither the stream before the latch nor the take-off after it may turn
that into a jump in what is sent: no climb of the altitude floor's at the latch, no pull towards a
deck the estimate misplaces, the position sent continuous, and never a position above the
estimate while seated (PX4's take-off), whatever the HEARTBEAT last said of arming."""
from __future__ import annotations

import numpy as np
import pytest

from mission.config.schema import load_config
from mission.controller import mission_model
from mission.core.law import norm
from mission.core.setpoint import Setpoint
from mission.phases import CarrierObs, MissionState, Observation, Phase, VehicleObs, step
from mission.phases.deck import held_down
from tests.conftest import CONFIGS

DECK = np.array([0.0, 0.0, -0.5])  # the deck (the dock point) above the carrier's position [m] NED
#: the seated vehicle's estimate: 0.25 m ahead, 0.1 m right and 0.41 m below the deck (seed 0's
#: first separation, `marsupial demo --config configs/cycle.toml`: under the floor, z_max_m -0.3)
ERROR = np.array([0.25, -0.1, 0.41])
POSITION_GAIN_PER_S = 1.0  # PX4's MPC_Z_P / MPC_XY_P (about): what a position setpoint adds to its velocity's


@pytest.fixture(scope="module")
def cycle():
    """configs/cycle.toml: full setpoints (position lead 2.6, bias compensation), the floor 0.2 m
    under the deck."""
    return mission_model(load_config(CONFIGS / "cycle.toml"))


@pytest.fixture(scope="module")
def velocity():
    """demo.toml riding the deck, velocity setpoints pulling 1.5/s towards the reference."""
    cfg = load_config(CONFIGS / "demo.toml")
    mission = cfg.mission.model_copy(update={"setpoint": "velocity", "track_gain": 1.5, "position_lead": 0.0,
                                             "drag_ff_per_s": 0.0, "integral_gain": 0.0, "ride": "deck",
                                             "dock_offset_ned_m": list(DECK)})
    return mission_model(cfg.model_copy(update={"mission": mission, "safety": cfg.safety.model_copy(update={"z_max_m": -0.3})}))


def effective(sp: Setpoint, x_p: np.ndarray) -> np.ndarray:
    """The velocity [m/s] PX4 flies on ``sp`` at its estimate ``x_p``: the setpoint's velocity plus
    its position loop's pull (nothing for velocity only)."""
    if sp.position_ned_m is None:
        return sp.velocity_ned_m_s
    return sp.velocity_ned_m_s + POSITION_GAIN_PER_S * (sp.position_ned_m - x_p)


def fly(model, error=ERROR, ticks=3000):
    """A kinematic world: the carrier drives at 2 m/s towards the target (at most 1 m/s^2) while
    the passenger rides; the vehicle sits on the deck, armed and in OFFBOARD when asked, until a
    setpoint asks for a climb by its estimate, then flies the velocity PX4 would (:func:`effective`).
    Its estimate is the truth plus ``error`` throughout. Returns per tick (phase, setpoint, the
    estimate, the carrier's velocity) from the first setpoint streamed to 3 s after the latch."""
    dt = model.dt_s
    x_c, v_c = np.zeros(3), np.zeros(3)
    x_p = x_c + DECK
    mode, armed, on_deck = "AUTO.LOITER", False, True
    state, out, sep = MissionState(), [], None
    for k in range(ticks):
        seen = x_p + error
        vehicle = VehicleObs(seen.copy(), (v_c if on_deck else np.zeros(3)).copy(), armed, mode, heartbeat_age_s=0.1,
                             on_ground=on_deck)
        state, dec = step(state, Observation(t_s=k * dt, vehicle=vehicle, carrier=CarrierObs(x_c.copy(), v_c.copy(), age_s=0.0)),
                          model)
        if dec.request == "arm":
            armed = True
        elif dec.request == "offboard" and armed:
            mode = "OFFBOARD"
        sp = dec.setpoint
        if sp is not None and state.phase != Phase.STREAMING:
            out.append((state.phase, sp, seen.copy(), v_c.copy()))
        if sep is None and state.phase == Phase.SEPARATED:
            sep = k
        if sep is not None and k - sep > 3.0 / dt:
            break
        want = np.zeros(3)
        if state.phase == Phase.RIDING:
            e = model.tick.target - x_c
            e[2] = 0.0
            want = e / norm(e) * 2.0
        dv = want - v_c
        v_c = v_c + dv * min(1.0, dt / max(float(norm(dv)), 1e-12))
        x_c = x_c + v_c * dt
        if on_deck and armed and mode == "OFFBOARD" and sp is not None and (
                sp.velocity_ned_m_s[2] < 0 or (sp.position_ned_m is not None and sp.position_ned_m[2] < seen[2])
                or (sp.acceleration_ned_m_s2 is not None and sp.acceleration_ned_m_s2[2] < 0)):
            on_deck = False
            if state.phase == Phase.RIDING:
                pytest.fail(f"lifted off before the latch by {sp}")
        x_p = x_c + DECK if on_deck else x_p + effective(sp, seen) * dt
    assert sep is not None, "never separated"
    return out


@pytest.mark.parametrize("name", ["cycle", "velocity"])
def test_the_take_off_on_a_misplacing_estimate_sends_no_jump(name, request):
    """From the first setpoint streamed on the deck through the latch and 1 s of the take-off, the
    relative velocity sent (``u_cmd - v_c``) starts at zero and changes per tick by at most the
    ramp the acceleration limits allow (the command's, ``command_safety``, plus the braking
    carrier's 1 m/s^2, over a tick, + 0.01: 0.09 m/s; 0.057-0.058 measured), its vertical part by
    at most the project's 0.05 m/s (0.045-0.046 measured: the law's climb at the passenger's 2
    m/s^2 and the offset's relaxation, TAKEOFF_RELAX). On main the
    floor's climb (the estimate 0.41 m below the deck, 0.21 m under the floor) came at the latch at
    once: 0.2 m/s up in one tick."""
    model = request.getfixturevalue(name)
    out = fly(model)
    sep = next(i for i, (p, *_) in enumerate(out) if p == Phase.SEPARATED)
    assert out[0][0] == Phase.RIDING
    rel = np.array([sp.velocity_ned_m_s - v_c for _, sp, _, v_c in out[:sep + 50]])
    assert np.linalg.norm(rel[0]) <= 1e-9  # the first setpoint streamed: the deck's velocity
    steps = np.diff(rel, axis=0)
    a_cmd = model.command_safety.max_accel_m_s2  # [m/s^2]
    assert np.linalg.norm(steps, axis=1).max() <= (a_cmd + 1.0) * model.dt_s + 0.01
    assert np.abs(steps[:, 2]).max() <= 0.05


def test_seated_the_position_sent_is_never_above_the_estimate(cycle):
    """PX4 arms before its HEARTBEAT says so and reads the setpoint against its estimate at once:
    held down, the position is press_m below the reported height whether the vehicle says it is
    armed or not, and however low the estimate reads it (below the landing's floor too). On main a
    vehicle reporting itself disarmed was pressed only 0.1 m into the deck's plane: with its
    estimate 0.112 m below the deck that was a position 0.012 m above it, PX4's take-off (seed 0,
    3.2 s before the second latch, at its arming; it came down on the deck at 0.41 m/s)."""
    dock = DECK.copy()
    press = cycle.deck.press_m
    climbing = Setpoint(np.array([1.5, 0.0, -0.2]), dock.copy(), np.zeros(3))
    for armed in (False, True):
        for below in (0.112, 0.3, 0.55, 0.8):  # the estimate this far below the deck's plane [m]
            at = dock + np.array([0.1, 0.0, below])
            vehicle = VehicleObs(at, np.array([1.5, 0.0, 0.0]), armed, "OFFBOARD", heartbeat_age_s=0.0, on_ground=True)
            obs = Observation(t_s=10.0, vehicle=vehicle, carrier=CarrierObs(np.zeros(3), np.array([1.5, 0.0, 0.0]), age_s=0.0))
            held = held_down(climbing, dock, obs, cycle)
            assert held.position_ned_m[2] >= at[2] + press - 1e-12, (armed, below)
            assert held.velocity_ned_m_s[2] >= 0.0 and held.acceleration_ned_m_s2[2] >= 0.0
