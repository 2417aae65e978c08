"""The mission state machine, driven by synthetic observations (pure, no sockets)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mission.config.schema import load_config
from mission.controller import mission_model
from mission.bus.wire import WireError
from mission.core.law import norm
from mission.core.safety import Neighbours
from mission.phases import AbortReason, CarrierObs, MissionState, Observation, Phase, VehicleObs, finished, step
from tests.conftest import CONFIGS


@pytest.fixture(scope="module")
def model():
    """demo.toml's mission flown by velocity setpoints: the synthetic world below integrates the
    setpoint as a velocity (it has no position loop of PX4's to close a full setpoint's position)."""
    cfg = load_config(CONFIGS / "demo.toml")
    mission = cfg.mission.model_copy(update={"setpoint": "velocity", "track_gain": 1.5, "position_lead": 0.0,
                                             "drag_ff_per_s": 0.0, "integral_gain": 0.0})
    return mission_model(cfg.model_copy(update={"mission": mission}))


def fly(model, *, ticks=4000, carrier_age=0.0, on_tick=None, vehicle_tau=0.0):
    """A perfect kinematic world: the vehicle integrates the setpoint (optionally through a first
    order lag), the carrier drives at 2 m/s towards the target while the machine says RIDING."""
    dt = model.dt_s
    x_p = np.zeros(3)
    v_p = np.zeros(3)
    x_c = np.zeros(3)
    v_c = np.zeros(3)
    mode, armed = "AUTO.LOITER", False
    state = MissionState()
    log = []
    for k in range(ticks):
        t = k * dt
        vehicle = VehicleObs(x_p.copy(), v_p.copy(), armed, mode, heartbeat_age_s=0.1)
        carrier = CarrierObs(x_c - v_c * carrier_age, v_c.copy(), age_s=carrier_age)
        obs = Observation(t_s=t, vehicle=vehicle, carrier=carrier)
        if on_tick:
            obs = on_tick(k, obs) or obs
        state, dec = step(state, obs, model)
        log.append((t, state.phase, dec))
        if dec.request == "arm":
            armed = True
        elif dec.request == "offboard":
            mode = "OFFBOARD"
        elif dec.request == "hold":
            mode = "AUTO.LOITER"
        if dec.setpoint is not None and mode == "OFFBOARD":
            assert dec.setpoint.is_finite() and not dec.setpoint.full
            v_sp = dec.setpoint.velocity_ned_m_s
            v_p = v_sp if vehicle_tau == 0 else v_p + (v_sp - v_p) * dt / vehicle_tau
        elif mode != "OFFBOARD":
            v_p = np.zeros(3)
        x_p = x_p + v_p * dt
        if state.phase == Phase.RIDING and state.held_dock is None:  # a holding passenger pauses the carrier
            e = model.tick.target - x_c
            e[2] = 0.0
            v_c = e / norm(e) * 2.0
        else:
            v_c = np.zeros(3)
        x_c = x_c + v_c * dt
        if finished(state, dec):
            break
    return state, log, x_p, x_c


def test_perfect_world_completes_and_latches_at_bc(model):
    state, log, x_p, x_c = fly(model)
    phases = list(dict.fromkeys(p for _, p, _ in log))
    assert phases == [Phase.STREAMING, Phase.ARMING, Phase.OFFBOARD, Phase.JOIN, Phase.RIDING, Phase.SEPARATED,
                      Phase.NAVIGATING, Phase.ARRIVED, Phase.HOLD, Phase.DONE]
    # the latch is located inside the tick: the anchor sits at b c - margin exactly
    assert norm(model.tick.target - state.anchor) == pytest.approx(model.tick.event_distance_m, abs=1e-9)
    assert norm(x_p - model.tick.target) <= model.arrival_radius_m


def test_relative_command_continuous_across_separation(model):
    state, log, _, _ = fly(model, vehicle_tau=0.2)
    i = next(k for k, (_, p, _) in enumerate(log) if p == Phase.SEPARATED)
    before, after = log[i - 1][2], log[i][2]
    # the law's relative input: exactly 0 docked, ~8 mm/s just after (no jump)
    assert norm(before.relative) == 0.0
    assert norm(after.relative) < 0.02
    # the command sent changes by at most one tick of the command's acceleration limit
    a_max = model.command_safety.max_accel_m_s2
    assert norm(after.setpoint.velocity_ned_m_s - before.setpoint.velocity_ned_m_s) <= a_max * model.dt_s + 1e-9


def test_late_carrier_samples_are_extrapolated(model):
    # Samples 0.3 s old while the carrier drives at 2 m/s: the dock point is moved on by
    # v * age, so the vehicle rides where the carrier really is, not 0.6 m behind it.
    offsets = []

    def watch(k, obs):
        c = obs.carrier
        if norm(c.velocity_ned_m_s) > 1.9:  # riding at full carrier speed
            true_dock = c.position_ned_m + c.velocity_ned_m_s * c.age_s + model.dock_offset_ned_m
            offsets.append(norm(obs.vehicle.position_ned_m - true_dock))

    state, _, _, _ = fly(model, carrier_age=0.3, on_tick=watch)
    assert state.phase == Phase.DONE
    assert len(offsets) > 100 and max(offsets[len(offsets) // 2:]) < 0.05  # after the start transient


def test_pilot_override_sends_nothing_more(model):
    def pilot(k, obs):
        if k > 600:
            return Observation(obs.t_s, VehicleObs(obs.vehicle.position_ned_m, obs.vehicle.velocity_ned_m_s, True, "POSCTL", 0.1),
                               obs.carrier)

    state, log, _, _ = fly(model, on_tick=pilot)
    assert state.phase == Phase.ABORT and state.reason == AbortReason.PILOT_OVERRIDE
    assert log[-1][2].setpoint is None and log[-1][2].request is None


def test_geometry_refusal_sends_nothing(model):
    def far(k, obs):
        v = obs.vehicle
        return Observation(obs.t_s, VehicleObs(v.position_ned_m + [3.0, 0, 0], v.velocity_ned_m_s, False, v.mode, 0.1), obs.carrier)

    state, log, _, _ = fly(model, on_tick=far, ticks=10)
    assert state.reason == AbortReason.GEOMETRY
    assert all(d.setpoint is None and d.request is None for _, _, d in log)


@pytest.mark.parametrize("what, reason, detail", [
    ("no vehicle", AbortReason.VEHICLE_LOST, "no vehicle"),
    ("no carrier", AbortReason.CARRIER_LOST, "no carrier"),
    ("silent vehicle", AbortReason.VEHICLE_LOST, "vehicle silent"),
    ("no position", AbortReason.POSITION_LOST, "no vehicle position"),
])
def test_preflight_timeout_names_what_is_missing(model, what, reason, detail):
    """Before anything is sent, the abort names the missing piece; a vehicle that is heard but has
    no position is not the carrier's fault."""
    def world(k, obs):
        v, c = obs.vehicle, obs.carrier
        if what == "no vehicle":
            v = None
        elif what == "silent vehicle":
            v = VehicleObs(v.position_ned_m, v.velocity_ned_m_s, False, v.mode, heartbeat_age_s=10.0)
        elif what == "no position":
            v = VehicleObs(v.position_ned_m, v.velocity_ned_m_s, False, v.mode, 0.1, position_valid=False)
        if what == "no carrier":
            c = None
        return Observation(obs.t_s, v, c)

    ticks = int((model.connect_timeout_s + 1.0) / model.dt_s)
    state, log, _, _ = fly(model, on_tick=world, ticks=ticks)
    assert (state.phase, state.reason) == (Phase.ABORT, reason.value)
    assert any(f"abort: preflight: {detail}" in d.events for _, _, d in log)
    assert all(d.setpoint is None and d.request in (None, "hold") for _, _, d in log)


def test_stale_carrier_before_separation_aborts_to_hold(model):
    def stale(k, obs):
        if k > 500:
            c = obs.carrier
            return Observation(obs.t_s, obs.vehicle, CarrierObs(c.position_ned_m, c.velocity_ned_m_s, age_s=2.0))

    state, log, _, _ = fly(model, on_tick=stale, ticks=700)
    assert state.reason == AbortReason.CARRIER_LOST
    assert any(d.request == "hold" for _, p, d in log if p == Phase.ABORT)


def test_mission_too_long_holds(model):
    state, log, _, _ = fly(replace(model, max_duration_s=8.0))
    assert state.reason == AbortReason.TIMEOUT
    assert any(d.request == "hold" for _, p, d in log if p == Phase.ABORT)
    assert log[-1][2].setpoint is None  # once Hold shows, nothing more is sent


def test_riding_feeds_forward_the_acceleration_the_carrier_sent_capped_else_the_laws():
    """A carrier that measures its acceleration sends it (a PX4 rover sticks, then leaps: not its
    law); the passenger feeds that forward, capped at its own acceleration limit; without one it
    predicts the law's: a_max along the command from rest."""
    from mission.phases.flying import _carrier_acceleration

    model = mission_model(load_config(CONFIGS / "demo.toml"))
    cap = model.command_safety.max_accel_m_s2
    assert cap is not None
    vehicle = VehicleObs(np.zeros(3), np.zeros(3), True, "OFFBOARD", heartbeat_age_s=0.1)

    def obs(accel):
        return Observation(1.0, vehicle, CarrierObs(np.zeros(3), np.zeros(3), 0.0, acceleration_ned_m_s2=accel))

    np.testing.assert_allclose(_carrier_acceleration(obs(np.array([0.3, -0.2, 0.0])), model), [0.3, -0.2, 0.0])
    big = _carrier_acceleration(obs(np.array([0.0, 50.0, 0.0])), model)
    np.testing.assert_allclose(big, [0.0, cap, 0.0])  # a feed-forward, never more than the passenger may do
    law = _carrier_acceleration(obs(None), model)
    assert norm(law) == pytest.approx(model.tick.carrier_safety.max_accel_m_s2, rel=1e-6)
    e = model.tick.target - np.zeros(3)
    assert float(np.dot(law, e)) > 0  # towards the target


def test_the_laws_acceleration_over_a_horizon_is_no_bang_bang_on_velocity_noise():
    """At its speed limit the law asks no acceleration; an estimated velocity 0.1 m/s under it
    reads a_max over one carrier step (the noise's bang-bang that rocked the relnav ride) and
    0.1 / horizon over mission.carrier_accel_horizon_s. From rest it is a_max either way."""
    from mission.phases.flying import _carrier_acceleration

    model = mission_model(load_config(CONFIGS / "relnav.toml"))
    assert model.carrier_accel_horizon_s == 0.5
    a_max = model.tick.carrier_safety.max_accel_m_s2
    speed = model.tick.carrier_safety.max_speed_m_s
    assert a_max is not None and speed is not None
    flat = np.array([*model.tick.target[:2], 0.0])
    along = flat / norm(flat)  # the planar carrier heads for the target in the plane
    far = flat - 50.0 * along  # cruising: the law's command is the speed limit
    vehicle = VehicleObs(np.zeros(3), np.zeros(3), True, "OFFBOARD", heartbeat_age_s=0.1)

    def accel(m, v):
        return _carrier_acceleration(Observation(1.0, vehicle, CarrierObs(far, v * along, 0.0)), m)

    one_step = replace(model, carrier_accel_horizon_s=0.0)
    assert norm(accel(one_step, speed - 0.1)) == pytest.approx(a_max, rel=1e-6)
    assert float(np.dot(accel(model, speed - 0.1), along)) == pytest.approx(0.1 / 0.5, rel=1e-3)
    assert norm(accel(model, speed)) == pytest.approx(0.0, abs=1e-9)
    assert norm(accel(model, 0.0)) == pytest.approx(a_max, rel=1e-6)


def test_a_late_carrier_state_is_ridden_where_the_carrier_is_now_with_its_acceleration():
    """Riding a 0.3 s old state of a carrier pulling away from rest at a_max: the velocity fed
    forward is the sample's plus a_max x 0.3 s, the dock point moved on by the mean velocity;
    at its speed limit the law leads nothing; a stale state is not led."""
    from mission.phases.flying import _ridden_dock

    model = mission_model(load_config(CONFIGS / "relnav.toml"))
    a_max = model.tick.carrier_safety.max_accel_m_s2
    speed = model.tick.carrier_safety.max_speed_m_s
    assert a_max is not None and speed is not None
    flat = np.array([*model.tick.target[:2], 0.0])
    along = flat / norm(flat)
    far = flat - 50.0 * along
    vehicle = VehicleObs(np.zeros(3), np.zeros(3), True, "OFFBOARD", heartbeat_age_s=0.1)

    def ridden(v, fresh=True, age=0.3):
        return _ridden_dock(Observation(1.0, vehicle, CarrierObs(far, v * along, age)), model, fresh)

    dock, v_now, _ = ridden(0.5)
    np.testing.assert_allclose(v_now, (0.5 + a_max * 0.3) * along, atol=1e-9)
    np.testing.assert_allclose(dock, far + 0.5 * 0.3 * along + 0.5 * a_max * 0.3 ** 2 * along + model.dock_offset_ned_m,
                               atol=1e-9)
    _, v_now, _ = ridden(speed)
    np.testing.assert_allclose(v_now, speed * along, atol=1e-9)
    dock, v_now, a = ridden(0.5, fresh=False)
    np.testing.assert_allclose(v_now, 0.5 * along, atol=1e-12)
    assert norm(a) == 0.0


def test_riding_feeds_forward_the_estimated_deck_acceleration_not_the_laws_when_asked():
    """configs/px4_sitl_relnav.toml (relnav.carrier_accel_tau_s > 0): a rover cruising at its own
    1.1 m/s, under the law's 2 m/s, its state 0.3 s old. By the law it would be speeding up at
    a_max: the ride led it by a_max x 0.3 s of velocity and a_max of acceleration, and rode 0.3-0.45 m
    ahead of the deck on PX4. With the estimate's acceleration (here 0, and a vertical that a planar
    carrier never has) the velocity fed forward is the carrier's, the acceleration the estimate's."""
    from mission.phases.flying import _ridden_dock
    from mission.phases.types import RelativeView

    model = mission_model(load_config(CONFIGS / "px4_sitl_relnav.toml"))
    assert model.relnav is not None and model.relnav.carrier_accel_tau_s > 0
    a_max = model.tick.carrier_safety.max_accel_m_s2
    speed = model.tick.carrier_safety.max_speed_m_s
    assert a_max is not None and speed is not None and speed > 1.5
    flat = np.array([*model.tick.target[:2], 0.0])
    along = flat / norm(flat)
    far = flat - 50.0 * along
    vehicle = VehicleObs(np.zeros(3), np.zeros(3), True, "OFFBOARD", heartbeat_age_s=0.1)

    def ridden(accel):
        view = RelativeView(np.zeros(3), np.zeros(3), np.zeros(3), 0.02, True, 0.05,
                            carrier_accel_ned_m_s2=None if accel is None else np.asarray(accel, float))
        return _ridden_dock(Observation(1.0, vehicle, CarrierObs(far, 1.1 * along, 0.3), relative=view), model, True)

    dock, v_now, a = ridden([0.0, 0.0, 0.4])
    np.testing.assert_allclose(v_now, 1.1 * along, atol=1e-12)
    np.testing.assert_allclose(a, np.zeros(3), atol=1e-12)
    np.testing.assert_allclose(dock, far + 1.1 * 0.3 * along + model.dock_offset_ned_m, atol=1e-12)
    _, v_now, a = ridden(0.5 * along)
    np.testing.assert_allclose(v_now, (1.1 + 0.5 * 0.3) * along, atol=1e-12)
    np.testing.assert_allclose(a, 0.5 * along, atol=1e-12)
    _, v_now, a = ridden(None)  # no estimate of it: the law's, speeding up at a_max
    np.testing.assert_allclose(v_now, (1.1 + a_max * 0.3) * along, atol=1e-9)
    assert norm(a) == pytest.approx(a_max, rel=1e-6)


def test_the_carriers_law_is_predicted_where_the_carrier_says_it_is_not_in_the_passengers_frame():
    """No shared frame (configs/relnav.toml): the relative estimator moves the carrier's state into
    the passenger's frame, 2 m across from where the carrier's own GNSS puts it. The carrier steers
    by its law in its own frame: cruising at its speed limit straight at its target, 9 m away, its
    law asks no change. Run at the passenger-frame position the law's course turns by ~0.2 rad,
    and the ride fed forward 0.2-0.25 m/s across the carrier's velocity and 0.4 m/s^2 of acceleration
    (the relnav demo's rider drifted to 0.31 m off its dock point before the separation)."""
    from mission.phases.flying import _carrier_acceleration, _ridden_dock

    model = mission_model(load_config(CONFIGS / "relnav.toml"))
    speed = model.tick.carrier_safety.max_speed_m_s
    assert speed is not None and model.relnav is not None and model.relnav.carrier_accel_tau_s == 0
    flat = np.array([*model.tick.target[:2], 0.0])
    along = flat / norm(flat)
    across = np.array([-along[1], along[0], 0.0])
    own = flat - 9.0 * along  # where the carrier says it is: heading straight for the target
    passenger_frame = own + 2.0 * across
    vehicle = VehicleObs(np.zeros(3), np.zeros(3), True, "OFFBOARD", heartbeat_age_s=0.1)

    def obs(own_frame):
        return Observation(1.0, vehicle, CarrierObs(passenger_frame, speed * along, 0.25, own_frame_position_ned_m=own_frame))

    _, v_now, a = _ridden_dock(obs(own), model, True)
    np.testing.assert_allclose(v_now, speed * along, atol=1e-9)
    np.testing.assert_allclose(_carrier_acceleration(obs(own), model), np.zeros(3), atol=1e-9)
    _, v_wrong, _ = _ridden_dock(obs(None), model, True)  # the law run in the passenger's frame
    assert abs(float(np.dot(v_wrong, across))) > 0.05  # over the 0.25 s of age, at the law's acceleration limit
    assert norm(_carrier_acceleration(obs(None), model)) > 0.2


@pytest.mark.parametrize("p3_frame", ["own", "passenger"])
def test_the_relative_deck_keeps_where_the_carrier_s_law_runs(p3_frame: str):
    """The carrier's state moved into the passenger's frame keeps its published position for its
    law when that runs in the carrier's own frame (``carrier.p3_frame = "own"``); with
    ``"passenger"`` the law runs in the passenger's frame, at the moved position."""
    from mission.config.schema import with_overrides
    from mission.passenger.inputs import VehicleReport
    from mission.passenger.relative import RelativeDeck
    from mission.phases.measurements import Measurements

    model = mission_model(with_overrides(load_config(CONFIGS / "relnav.toml"), {"carrier.p3_frame": p3_frame}))
    assert model.relnav is not None
    deck = RelativeDeck(model.relnav, model.dock_offset_ned_m)
    published = np.array([3.0, 4.0, 0.0])
    carrier = CarrierObs(published, np.array([1.0, 0.0, 0.0]), 0.2)
    seen = None
    for k in range(5):
        t = 0.1 * (k + 1)
        report = VehicleReport(t, np.array([0.0, 0.0, -2.0]), np.zeros(3), t, t, True, "OFFBOARD", 0.1, True)
        seen, _ = deck.observe(t, report, replace(carrier, age_s=0.2 - 0.1 * k if k < 2 else 0.0), Measurements())
    assert seen is not None
    if p3_frame == "own":
        np.testing.assert_allclose(seen.own_frame_position_ned_m, published)
        np.testing.assert_allclose(seen.law_position_ned_m, published)
    else:
        assert seen.own_frame_position_ned_m is None
        np.testing.assert_array_equal(seen.law_position_ned_m, seen.position_ned_m)


def test_a_phase_is_defined_once_and_every_part_knows_it():
    """The Phase enum is the one list: the machine handles each (DONE and ABORT in its failsafes),
    the wire carries each by name, the carrier has a duty for each."""
    from mission.bus.wire import PassengerStatus
    from mission.carrier.modes import CarrierMode, PassengerView, next_mode
    from mission.phases.machine import HANDLERS

    assert set(HANDLERS) | {Phase.DONE, Phase.ABORT} == set(Phase)
    for phase in Phase:
        status = PassengerStatus(phase, 1.0, 1, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], separated=phase.separated)
        assert PassengerStatus.from_json(status.to_json()).phase is phase
        mode, _ = next_mode(CarrierMode.WAITING, PassengerView(phase, phase.separated))
        assert mode in CarrierMode
    with pytest.raises(WireError) as err:
        PassengerStatus.from_json(b'{"phase": "FLYING", "stamp": 1, "seq": 1, "position": [0,0,0], '
                                  b'"velocity": [0,0,0], "separated": false}')
    assert err.value.reason == "phase"


# ----------------------------------------------------------------------------- armed and landed


def _first_tick(model, phase):
    _, log, _, _ = fly(model)
    return next(k for k, (_, p, _) in enumerate(log) if p == phase)


@pytest.mark.parametrize("phase, fault", [(Phase.OFFBOARD, "disarmed"), (Phase.JOIN, "disarmed"),
                                          (Phase.RIDING, "disarmed"), (Phase.NAVIGATING, "disarmed"),
                                          (Phase.RIDING, "landed"), (Phase.NAVIGATING, "landed")])
def test_a_vehicle_disarmed_or_landed_in_flight_aborts_at_once_and_is_never_flown_again(model, phase, fault):
    """A forced disarm (a rogue ground station's COMPONENT_ARM_DISARM with 21196) or PX4's land
    detector saying ON_GROUND where the mission needs the vehicle armed or in the air: abort
    vehicle_disarmed on the tick that sees it, with nothing sent (no setpoint, no Hold request);
    re-armed and put back in OFFBOARD by someone else, it stays aborted and nothing is sent."""
    at = _first_tick(model, phase) + 1  # the first tick that runs in that phase

    def rogue(k, obs):
        if k >= at:
            v = obs.vehicle
            return replace(obs, vehicle=replace(v, armed=False) if fault == "disarmed" else replace(v, on_ground=True))

    state, log, _, _ = fly(model, on_tick=rogue)
    assert (state.phase, state.reason) == (Phase.ABORT, AbortReason.VEHICLE_DISARMED)
    assert len(log) == at + 1 and log[at - 1][1] == phase  # the tick that saw it aborted
    last = log[-1][2]
    assert last.setpoint is None and last.request is None
    assert any(e.startswith(f"abort: vehicle {fault} in {phase.value}") for e in last.events), last.events
    # someone else re-arms it and puts it back in OFFBOARD, in the air: still aborted, hands off
    again = VehicleObs(np.array([5.0, 5.0, -3.0]), np.zeros(3), True, "OFFBOARD", heartbeat_age_s=0.1)
    carrier = CarrierObs(np.zeros(3), np.zeros(3), age_s=0.0)
    for k in range(1, 50):
        state, dec = step(state, Observation(log[-1][0] + k * model.dt_s, again, carrier), model)
        assert state.phase == Phase.ABORT and dec.setpoint is None and dec.request is None


def test_the_land_detector_on_the_deck_before_take_off_is_no_fault(model):
    """PX4 says ON_GROUND until it has seen the take-off (2-2.5 s into JOIN on SITL): only the
    phases after JOIN need the vehicle in the air."""
    def detector(k, obs):
        v = obs.vehicle
        return replace(obs, vehicle=replace(v, on_ground=bool(v.position_ned_m[2] > -0.2)))

    state, log, _, _ = fly(model, on_tick=detector)
    assert state.phase == Phase.DONE
    assert any(p == Phase.JOIN and d.setpoint is not None for _, p, d in log)


def test_disarmed_during_an_abort_to_hold_stops_the_stream(model):
    """Aborted (carrier lost) and streaming zero velocity until Hold shows: disarmed meanwhile,
    the stream and the Hold request stop at once."""
    state = MissionState(phase=Phase.ABORT, reason=AbortReason.CARRIER_LOST, start_s=0.0)
    riding = VehicleObs(np.array([5.0, 5.0, -1.5]), np.zeros(3), True, "OFFBOARD", heartbeat_age_s=0.1)
    carrier = CarrierObs(np.zeros(3), np.zeros(3), age_s=2.0)
    state, dec = step(state, Observation(1.0, riding, carrier), model)
    assert dec.request == "hold" and dec.setpoint is not None  # still OFFBOARD: zeros until Hold shows
    state, dec = step(state, Observation(1.02, replace(riding, armed=False), carrier), model)
    assert state.phase == Phase.ABORT and dec.setpoint is None and dec.request is None and finished(state, dec)


@pytest.mark.parametrize("phase", [Phase.PREFLIGHT, Phase.RIDING])
def test_a_second_autopilot_without_target_system_aborts(model, phase):
    """The link reports a second PX4 autopilot (``failed["identity"]``, mavlink.target_system unset):
    abort vehicle_ambiguous; before anything was sent nothing is, in flight Hold is asked."""
    at = 0 if phase == Phase.PREFLIGHT else _first_tick(model, phase) + 3
    text = "a second PX4 autopilot sysid 42 compid 1 talks"

    def world(k, obs):
        return replace(obs, failed={**obs.failed, "identity": text}) if k >= at else None

    state, log, _, _ = fly(model, on_tick=world)
    assert (state.phase, state.reason, state.detail) == (Phase.ABORT, AbortReason.VEHICLE_AMBIGUOUS, text)
    first = log[at][2]
    assert f"abort: {text}" in first.events
    if phase == Phase.PREFLIGHT:
        assert first.setpoint is None and first.request is None
    else:
        assert first.request == "hold"


def test_an_untrusted_carrier_state_never_fires_the_latch_the_passenger_holds_then_rejoins(model):
    """Mid-approach the feed follows a track 7 m from the target (a spoofed burst, or a
    relocalisation) that it does not trust yet: the passenger holds on the dock point it had (the
    carrier pauses), never separates on it, and once the honest track is trusted again it goes
    back to the dock point at join speed and separates at b c of the real carrier."""
    target = model.tick.target
    short = target - np.array([7.0, 0.0, target[2]])  # 7 m short of the target, on the ground plane
    phase = {"spoof": 0, "settle": 0}
    holding = []

    def attack(k, obs):
        c = obs.carrier
        if norm(c.position_ned_m) < 3.0 or phase["settle"] >= 100:
            return None
        if phase["spoof"] < 150:  # 3 s on the spoofed track, untrusted
            phase["spoof"] += 1
            return Observation(obs.t_s, obs.vehicle, CarrierObs(short, np.zeros(3), 0.0, untrusted="settling: after a resync"))
        phase["settle"] += 1  # the honest track again, settling for 2 s
        return Observation(obs.t_s, obs.vehicle, CarrierObs(c.position_ned_m, c.velocity_ned_m_s, 0.0,
                                                            untrusted="settling: after a resync"))

    def watch(k, obs):
        out = attack(k, obs)
        holding.append((out or obs).carrier.untrusted is not None)
        return out

    state, log, x_p, x_c = fly(model, on_tick=watch, ticks=6000)
    assert state.phase == Phase.DONE and phase["settle"] == 100
    sep = next(k for k, (_, p, _) in enumerate(log) if p == Phase.SEPARATED)
    assert not any(holding[sep - 1:sep + 1])  # the latch fired on a trusted state ...
    assert norm(target - state.anchor) == pytest.approx(model.tick.event_distance_m, abs=1e-9)  # ... of the real carrier
    held = [k for k, h in enumerate(holding) if h]
    assert len(held) == 250 and sep > held[-1]
    refs = [log[k][2].setpoint.velocity_ned_m_s for k in held]  # holding: the reference stands still, the vehicle settles on it
    assert norm(refs[-1]) < 0.05
    events = [e for _, _, d in log for e in d.events]
    assert any(e.startswith("carrier feed not trusted (settling: after a resync)") for e in events)
    assert "carrier feed trusted again: back on the dock point, riding" in events


@pytest.mark.parametrize("what", ["vehicle at infinity", "carrier at 1e308 m"])
def test_a_non_finite_value_aborts_to_hold_naming_it(model, what):
    """Nothing non-finite is ever sent: the tick that would compute one aborts (nonfinite) and
    asks for Hold (the fly world asserts every setpoint it gets is finite)."""
    def corrupt(k, obs):
        v, c = obs.vehicle, obs.carrier
        if norm(c.position_ned_m) < 5.0:
            return None
        if what == "vehicle at infinity":
            return Observation(obs.t_s, VehicleObs(np.array([np.inf, 0, -1.5]), v.velocity_ned_m_s, v.armed, v.mode, 0.1), c)
        return Observation(obs.t_s, v, CarrierObs(np.array([1e308, 1e308, 0.0]), c.velocity_ned_m_s, 0.0))

    state, log, _, _ = fly(model, on_tick=corrupt, ticks=3000)
    assert (state.phase, state.reason) == (Phase.ABORT, AbortReason.NONFINITE.value)
    assert state.detail.startswith("non-finite ") and state.detail.endswith("in RIDING")
    aborted = next(d for _, p, d in log if p == Phase.ABORT)
    assert aborted.request == "hold" and any(e.startswith("abort: non-finite") for e in aborted.events)


def test_navigating_keeps_apart_from_a_neighbour_on_its_way(model):
    """A neighbour hovers half-way between where the passenger separates and its target (the
    observation's ``neighbours``, as the step passes them on): the reference goes round it at
    the separation distance; the vehicle, which tracks it, within a small tracking lag. Alone,
    the passenger passes within a metre of it."""
    target = model.tick.target
    dock_z = float(model.dock_offset_ned_m[2])
    reach = np.sqrt(model.tick.event_distance_m**2 - (target[2] - dock_z) ** 2)  # horizontal, at the latch
    heading = target[:2] / norm(target[:2])
    anchor = np.array([*(target[:2] - reach * heading), dock_z])
    hover = 0.5 * (anchor + target)
    neighbours = Neighbours(hover[None], np.zeros((1, 3)), np.zeros(1))
    D = model.tick.passenger_safety.separation_m
    closest = {}

    def watch(name):
        def on_tick(k, obs):
            if obs.vehicle is not None:
                closest[name] = min(closest.get(name, np.inf), float(norm(obs.vehicle.position_ned_m - hover)))
            return replace(obs, neighbours=neighbours) if name == "kept" else obs
        return on_tick

    fly(model, on_tick=watch("alone"))
    state, _, x_p, _ = fly(model, on_tick=watch("kept"))
    assert closest["alone"] < 1.0, closest
    assert closest["kept"] >= D - 0.1, closest  # [m] the vehicle's lag behind the reference, which keeps D
    assert state.phase == Phase.DONE and norm(x_p - target) <= model.arrival_radius_m


def test_with_the_relative_estimate_the_altitude_floor_stands_over_the_ground_under_the_passenger():
    """The floor (z_max_m, the ground at 0) follows the carrier's height in the passenger's own
    frame when the relative estimator gives it (a 1 m vertical drift put the riding hover point
    on a fixed floor), at most 3 m either way; without the estimate it stays where configured."""
    from mission.core.safety import SafetyConfig
    from mission.phases.flying import FLOOR_GROUND_SHIFT_MAX_M, floor_over_the_ground
    from mission.phases.types import RelativeView

    limits = SafetyConfig(z_max_m=-0.5)
    vehicle = VehicleObs(np.zeros(3), np.zeros(3), True, "OFFBOARD", heartbeat_age_s=0.1)
    view = RelativeView(np.zeros(3), np.zeros(3), np.zeros(3), 0.05, True, 0.1)

    def floor(carrier_z, relative=view):
        obs = Observation(1.0, vehicle, CarrierObs(np.array([3.0, 4.0, carrier_z]), np.zeros(3), 0.0), relative=relative)
        return floor_over_the_ground(limits, obs).z_max_m

    assert floor(0.9) == pytest.approx(0.4)  # the ground 0.9 m lower in the passenger's frame
    assert floor(-0.7) == pytest.approx(-1.2)
    assert floor(50.0) == pytest.approx(-0.5 + FLOOR_GROUND_SHIFT_MAX_M)  # a wild height moves it 3 m at most
    assert floor(-50.0) == pytest.approx(-0.5 - FLOOR_GROUND_SHIFT_MAX_M)
    assert floor(0.9, relative=None) == -0.5  # one shared frame: the floor as configured


def test_the_floor_acting_down_leaves_the_horizontal_tracking_whole():
    """relnav.toml's full setpoints: a reference descending at 1 m/s into the altitude floor while
    it rides north. The floor's barrier changes only the vertical velocity, so the
    setpoint keeps north's and east's position and acceleration and sends down's velocity only;
    a demand over the speed limit changes every axis and goes velocity only."""
    from mission.phases.flying import _track

    model = mission_model(load_config(CONFIGS / "relnav.toml"))
    z_max = model.command_safety.z_max_m
    assert z_max is not None and model.tracking.kind == "full"
    x_p = np.array([10.0, 0.0, z_max - 0.05])  # 5 cm over the floor
    vehicle = VehicleObs(x_p, np.array([1.0, 0.0, 0.0]), True, "OFFBOARD", heartbeat_age_s=0.1)
    obs = Observation(1.0, vehicle, CarrierObs(np.array([10.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]), 0.0))
    state = MissionState(phase=Phase.RIDING, u_cmd=np.array([1.0, 0.0, 0.0]))
    tr = _track(state, obs, model, x_p.copy(), np.array([1.0, 0.0, 1.0]), np.zeros(3))
    assert tr.acted and tr.setpoint.kind == "full_horizontal"
    assert tr.setpoint.velocity_ned_m_s[2] < 0.5  # held back by the floor
    assert tr.setpoint.velocity_ned_m_s[0] == pytest.approx(1.0)  # north untouched
    speed = model.command_safety.max_speed_m_s
    assert speed is not None
    fast = _track(state, obs, model, x_p.copy(), np.array([3.0 * speed, 3.0 * speed, -0.5]), np.zeros(3))
    assert fast.acted and fast.setpoint.kind == "velocity"
