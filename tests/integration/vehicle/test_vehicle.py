"""Mock vehicle behaviour over real UDP on loopback (ephemeral ports), pymavlink as the client.

Modes, arming, OFFBOARD entry and loss, failsafes, auto-disarm, auto modes and kinematics.
Timing facts are checked in simulated time (the vehicle's event log stamps each event at the
physics step where it happened), so they hold at any speed factor and on a loaded machine.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from mission.mavlink import px4, setpoints
from mission.mavlink.env import mavlink
from sim.net import wait_for
from sim.vehicle.mock import PHYSICS_DT_S, MockVehicle, VehicleSnapshot
from sim.testing.probe import Lockstep, Probe, SetpointStream, connect, sleep_until, start_offboard, vehicle_for, wait_flight

pytestmark = pytest.mark.timeout(30)


def climb_to(v: MockVehicle, probe: Probe, altitude_m: float, stream: SetpointStream, timeout_s: float = 5.0) -> None:
    stream.set(velocity_ned_m_s=(0.0, 0.0, -2.0))
    wait_flight(v, lambda s: s.position_ned_m[2] <= -altitude_m, timeout_s, "did not climb")
    stream.set(velocity_ned_m_s=(0.0, 0.0, 0.0))


def test_heartbeat_identity_and_initial_hold(probe: Probe) -> None:
    with vehicle_for(probe, paced=True, speed=10.0):
        hb = probe.wait_for("HEARTBEAT", timeout_s=2.0)
        assert hb is not None
        header = hb.get_header()
        assert (header.srcSystem, header.srcComponent) == (1, 1)
        assert hb.get_msgbuf()[0] == 0xFD  # MAVLink 2
        assert (hb.type, hb.autopilot) == (px4.MAV_TYPE_QUADROTOR, px4.MAV_AUTOPILOT_PX4)
        assert hb.custom_mode == px4.custom_mode_of("AUTO.LOITER") == 50593792
        assert hb.base_mode == 29  # as seen on SITL: Hold, disarmed
        assert hb.system_status == px4.MAV_STATE_STANDBY
        ess = probe.wait_for("EXTENDED_SYS_STATE", timeout_s=2.0)
        assert ess is not None and ess.landed_state == px4.LANDED_ON_GROUND


def test_heartbeat_rate_is_1hz_simulated(probe: Probe) -> None:
    """1 Hz of simulated time. In lockstep (the probe moves the vehicle's time): at speed 20 in real
    time a loaded machine stalled the vehicle's loop for seconds of simulated time, and a stream
    due meanwhile goes out once, not once per missed period (3 HEARTBEATs counted instead of 6)."""
    with vehicle_for(probe, lockstep=True):
        clock = Lockstep(probe)
        clock.barrier()
        clock.run_for(7.0, lambda: None, period_s=0.1)
        assert probe.count_between("HEARTBEAT", 0.5, 6.5) == 6


def test_in_lockstep_nothing_but_the_hello_comes_before_the_first_answer(probe: Probe) -> None:
    """A controller bound before the vehicle's first datagram and one bound after it must start
    from the same samples: before any answer only the hello (HEARTBEAT, the barrier at t = 0) is
    sent, step 0's streams go to no one. (They went out with the first barrier, so a controller up
    in time read a first position that a later one never saw: with the estimate's errors two
    lockstep demos of one seed differed from their first row.) The first position comes after
    the first answer, stamped one physics step or more later."""
    with vehicle_for(probe, lockstep=True):
        clock = Lockstep(probe)
        assert clock.barrier() == 0
        before = {kind for kind in ("HEARTBEAT", "TIMESYNC", "LOCAL_POSITION_NED", "ATTITUDE", "SYSTEM_TIME")
                  if probe.messages(kind)}
        assert before == {"HEARTBEAT", "TIMESYNC"}, before
        clock.run_for(0.04, lambda: None, period_s=0.02)
        first = probe.messages("LOCAL_POSITION_NED")
        assert first and first[0].time_boot_ms >= 4, first[:1]


def test_in_lockstep_an_unanswered_barrier_is_sent_again_and_a_leave_for_an_earlier_step_ends_it(probe: Probe) -> None:
    """UDP loses datagrams: a barrier still unanswered after RESEND_WALL_S goes out again (a lost
    barrier or answer stalled the pair for good: the controller fell back after its 5 s, the
    vehicle waited 10 s, sending nothing, and the flight took it for lost). A controller that fell
    back while the vehicle's next barrier was lost says it leaves for its last step: the vehicle
    goes on in real time at once."""
    with vehicle_for(probe, lockstep=True) as v:
        clock = Lockstep(probe)
        clock.barrier()
        clock.run_for(0.1, lambda: None)
        t_ns, mark = clock.t_ns, probe.mark()
        again = probe.wait_for("TIMESYNC", lambda m: m.tc1 == 0 and m.ts1 == t_ns, 5.0, mark, wall=True)
        assert again is not None and v.snapshot().t_s == pytest.approx(t_ns / 1e9)  # sent again, not stepped
        clock.release(t_ns + 20_000_000)
        assert clock.barrier() > t_ns  # the answer to the resent barrier moves it on
        probe.send(mavlink.MAVLink_timesync_message(-1, t_ns))  # left at the step before this barrier
        wait_flight(v, lambda s: s.t_s > t_ns / 1e9 + 1.0, 5.0, "the vehicle going on in real time")  # its watchdog: 10 s


def test_offboard_rejected_without_setpoint_stream(probe: Probe) -> None:
    with vehicle_for(probe, paced=True) as v:
        connect(probe)
        ack = probe.set_mode("OFFBOARD")
        assert ack is not None and ack.result == px4.MAV_RESULT_TEMPORARILY_REJECTED
        assert probe.wait_for("STATUSTEXT", lambda m: "OFFBOARD" in m.text, 2.0) is not None
        assert v.snapshot().mode == "AUTO.LOITER"
        # armed with no stream: still rejected
        assert probe.arm().result == px4.MAV_RESULT_ACCEPTED
        assert probe.set_mode("OFFBOARD").result == px4.MAV_RESULT_TEMPORARILY_REJECTED


def test_offboard_accepted_with_stream_then_armed_and_flying(probe: Probe) -> None:
    with vehicle_for(probe, paced=True) as v:
        connect(probe)
        stream = start_offboard(probe, (0.0, 0.0, -1.0))
        with stream:
            assert probe.wait_mode("OFFBOARD") and probe.wait_armed(True)
            hb = probe.latest("HEARTBEAT")
            assert (hb.base_mode, hb.custom_mode, hb.system_status) == (145, 393216, px4.MAV_STATE_ACTIVE)
            snap = wait_flight(v, lambda s: s.position_ned_m[2] < -1.0, 3.0, "s.position_ned_m[2] < -1.0")
            assert snap is not None and snap.landed_state == px4.LANDED_IN_AIR
            assert probe.wait_for("EXTENDED_SYS_STATE", lambda m: m.landed_state == px4.LANDED_IN_AIR, 2.0)


def test_arming_in_offboard_without_fresh_stream_is_denied(probe: Probe) -> None:
    with vehicle_for(probe, paced=True, speed=20.0) as v:
        connect(probe)
        stream = start_offboard(probe, arm=False)
        stream.stop()
        t_stop = v.snapshot().last_setpoint_t_s
        wait_flight(v, lambda s: s.t_s > t_stop + 1.2, 2.0, "s.t_s > t_stop + 1.2")
        mark = probe.mark()
        ack = probe.arm()
        assert ack is not None and ack.result == px4.MAV_RESULT_TEMPORARILY_REJECTED
        assert probe.wait_for("STATUSTEXT", lambda m: "Arming denied" in m.text, 2.0, after=mark)
        assert not v.snapshot().armed


@pytest.mark.parametrize(("action", "mode"), [(0, "POSCTL"), (4, "AUTO.LAND"), (5, "AUTO.LOITER")])
def test_offboard_loss_failsafe_after_com_of_loss_t(probe: Probe, action: int, mode: str) -> None:
    loss_t_s = 1.0
    with vehicle_for(probe, paced=True, speed=20.0, params={"COM_OF_LOSS_T": loss_t_s, "COM_OBL_RC_ACT": action}) as v:
        connect(probe)
        stream = start_offboard(probe, (0.0, 0.0, -2.0))
        wait_flight(v, lambda s: s.position_ned_m[2] < -2.0, 3.0, "s.position_ned_m[2] < -2.0")
        stream.stop()
        assert probe.wait_mode(mode, 3.0)
        snap = v.snapshot()
        t_failsafe = v.event_time("Failsafe activated")
        assert t_failsafe is not None
        assert loss_t_s < t_failsafe - snap.last_setpoint_t_s <= loss_t_s + 2 * PHYSICS_DT_S
        assert snap.in_failsafe and snap.mode == mode
        hb = probe.wait_for("HEARTBEAT", lambda m: m.system_status == px4.MAV_STATE_CRITICAL, 3.0)
        assert hb is not None and px4.mode_name(hb.custom_mode) == mode
        assert probe.wait_for("STATUSTEXT", lambda m: "Failsafe activated" in m.text, 2.0)


def test_failsafe_without_rc_descends_lands_and_disarms(probe: Probe) -> None:
    with vehicle_for(probe, paced=True, speed=20.0, estimate_error=0.0) as v:  # exact: at rest to 0.01 m/s
        connect(probe)
        stream = start_offboard(probe, (1.0, 0.0, -2.0))
        wait_flight(v, lambda s: s.position_ned_m[2] < -3.0, 3.0, "s.position_ned_m[2] < -3.0")
        stream.stop()
        wait_flight(v, lambda s: s.mode == "POSCTL", 2.0, "s.mode == 'POSCTL'")
        # let the velocity settle, then watch a descent at about MPC_LAND_SPEED (PX4 SITL: 0.5-0.7 m/s)
        # while it brakes from 1 m/s north and holds its position
        start = wait_flight(v, lambda s: abs(s.velocity_ned_m_s[2] - 0.7) < 0.05, 2.0, "abs(s.velocity_ned_m_s[2] - 0.7) < 0.05")
        assert start is not None
        later = wait_flight(v, lambda s: s.t_s > start.t_s + 1.0, 2.0, "s.t_s > start.t_s + 1.0")
        assert later is not None
        rate = (later.position_ned_m[2] - start.position_ned_m[2]) / (later.t_s - start.t_s)
        assert rate == pytest.approx(0.68, abs=0.03)
        assert np.allclose(later.position_ned_m[:2], start.position_ned_m[:2], atol=0.4)
        assert np.hypot(*later.velocity_ned_m_s[:2]) < 0.4
        landed = wait_flight(v, lambda s: s.landed_state == px4.LANDED_ON_GROUND, 5.0, "s.landed_state == px4.LANDED_ON_GROUND")
        assert landed is not None and landed.position_ned_m[2] == 0.0
        assert probe.wait_armed(False, 3.0)
        t_landed = v.event_time("Landing detected")
        t_disarmed = v.event_time("Disarmed by landing")
        assert t_landed is not None and t_disarmed is not None
        assert t_disarmed - t_landed == pytest.approx(2.0, abs=2 * PHYSICS_DT_S)  # COM_DISARM_LAND


def test_failsafe_returns_to_offboard_when_setpoints_resume(probe: Probe) -> None:
    # a slow failsafe descent, so that it cannot land and disarm first on a loaded machine
    with vehicle_for(probe, paced=True, speed=5.0, params={"MPC_LAND_SPEED": 0.2}) as v:
        connect(probe)
        stream = start_offboard(probe, (0.0, 0.0, -3.0))
        wait_flight(v, lambda s: s.position_ned_m[2] < -2.0, 3.0, "s.position_ned_m[2] < -2.0")
        stream.stop()
        wait_flight(v, lambda s: s.mode == "POSCTL", 2.0, "s.mode == 'POSCTL'")
        t_failsafe = v.event_time("Failsafe activated")
        assert t_failsafe is not None
        probe.send(probe.setpoint_message((0.0, 0.0, 0.0)))  # a single setpoint: its arrival time is known
        snap = wait_flight(v, lambda s: s.mode == "OFFBOARD", 2.0, "s.mode == 'OFFBOARD'")
        assert snap is not None and not snap.in_failsafe and snap.armed
        t_back = v.event_time("Failsafe deactivated", after_s=t_failsafe)
        assert t_back is not None and 0.0 < t_back - snap.last_setpoint_t_s <= 0.2
        with SetpointStream(probe, 0.01, velocity_ned_m_s=(0.0, 0.0, 0.0)):
            assert probe.wait_mode("OFFBOARD", 2.0)


def test_auto_disarm_preflight_when_not_taking_off(probe: Probe) -> None:
    with vehicle_for(probe, paced=True, speed=20.0) as v:
        connect(probe)
        assert probe.arm().result == px4.MAV_RESULT_ACCEPTED
        assert probe.wait_armed(False, 3.0)
        t_armed, t_disarmed = v.event_time("Armed"), v.event_time("auto preflight disarming")
        assert t_armed is not None and t_disarmed is not None
        assert t_disarmed - t_armed == pytest.approx(10.0, abs=2 * PHYSICS_DT_S)  # COM_DISARM_PRFLT


def test_disarm_in_air_needs_force(probe: Probe) -> None:
    with vehicle_for(probe, paced=True) as v:
        connect(probe)
        with start_offboard(probe, (0.0, 0.0, -2.0)):
            wait_flight(v, lambda s: s.position_ned_m[2] < -1.0, 3.0, "s.position_ned_m[2] < -1.0")
            assert probe.arm(False).result == px4.MAV_RESULT_TEMPORARILY_REJECTED
            assert probe.arm(False, force=True).result == px4.MAV_RESULT_ACCEPTED
            # disarmed in the air: it falls (the timing of its landed state: tests/unit/vehicle/test_vehicle_modes.py)
            landed = wait_flight(v, lambda s: s.landed_state == px4.LANDED_ON_GROUND, 3.0, "landed state ON_GROUND")
            t_disarmed = v.event_time("Disarmed by external command")
            assert t_disarmed is not None and landed.t_s - t_disarmed >= 1.0 / 3.0 - PHYSICS_DT_S and not landed.armed
            down = wait_flight(v, lambda s: s.position_ned_m[2] >= 0.0, 3.0, "on the ground")
            assert down.mode == "OFFBOARD" and not down.armed and down.landed_state == px4.LANDED_ON_GROUND


def test_velocity_steps_answer_like_px4(probe: Probe) -> None:
    """PX4 SITL's recorded steps (../shared/px4_sitl/responses): a 2 m/s horizontal step peaks at
    79-84 % within 4 s (never 90 %: the small integrator against drag); a 1 m/s vertical step
    reaches 90 % in 0.5-0.9 s and peaks at 95-107 %. Measured on LOCAL_POSITION_NED. In lockstep
    (the probe moves the vehicle's time and streams the setpoint at 50 Hz simulated), so each step
    starts at a known simulated time whatever the machine's load."""
    with vehicle_for(probe, lockstep=True, start_ned=(0.0, 0.0, -1.0), estimate_error=0.0) as v:  # the airframe's own answer
        clock = Lockstep(probe)
        connect(probe)
        clock.barrier()
        setpoint = [(0.0, 0.0, -0.5)]

        def send() -> None:
            probe.send(probe.setpoint_message(velocity_ned_m_s=setpoint[0]))

        def now() -> float:
            return clock.t_ns / 1e9

        def step_to(velocity: tuple[float, float, float]) -> tuple[int, float]:
            """Change the setpoint at the current barrier: (probe mark, simulated time)."""
            setpoint[0] = velocity
            mark = probe.mark()
            send()
            return mark, now()

        def fly_until(done: Callable[[VehicleSnapshot], bool], limit_s: float) -> None:
            end_s = now() + limit_s
            while not done(v.snapshot()):
                assert now() < end_s, v.snapshot()
                clock.run_for(0.02, send, period_s=0.02)

        send()
        assert probe.set_mode("OFFBOARD").result == px4.MAV_RESULT_ACCEPTED
        assert probe.arm().result == px4.MAV_RESULT_ACCEPTED
        t_armed = now()
        fly_until(lambda s: s.position_ned_m[2] < -3.0, 10.0)
        step_to((0.0, 0.0, 0.0))
        fly_until(lambda s: s.t_s > t_armed + 4.0 and np.linalg.norm(s.velocity_ned_m_s) < 0.02, 10.0)
        mark, t_north = step_to((2.0, 0.0, 0.0))
        clock.run_for(4.0, send, period_s=0.02)
        north = [(m.time_boot_ms / 1000.0 - t_north, m.vx) for m in probe.messages("LOCAL_POSITION_NED", after=mark)]
        step_to((0.0, 0.0, 0.0))
        fly_until(lambda s: s.t_s > t_north + 10.0 and np.linalg.norm(s.velocity_ned_m_s) < 0.3, 10.0)
        mark, t_up = step_to((0.0, 0.0, -1.0))
        clock.run_for(3.0, send, period_s=0.02)
        up = [(m.time_boot_ms / 1000.0 - t_up, -m.vz) for m in probe.messages("LOCAL_POSITION_NED", after=mark)]
    peak = max(vx for t, vx in north if t <= 4.0) / 2.0
    assert 0.77 <= peak <= 0.86
    t90 = next(t for t, vz in up if vz >= 0.9)
    assert 0.4 <= t90 <= 0.8
    assert 0.95 <= max(vz for _, vz in up) <= 1.1  # PX4: 0.95-1.07


def test_velocity_limits(probe: Probe) -> None:
    """In lockstep (setpoints at 50 Hz simulated): at speed 10 in real time a setpoint stream
    stalled by a loaded machine slowed the vehicle (3.34 m/s at the end, not > 3.5)."""
    with vehicle_for(probe, lockstep=True, params={"MPC_XY_VEL_MAX": 4.0}) as v:
        clock = Lockstep(probe)
        connect(probe)
        clock.barrier()
        setpoint = [(0.0, 0.0, -10.0)]
        send = lambda: probe.send(probe.setpoint_message(velocity_ned_m_s=setpoint[0]))  # noqa: E731
        send()
        assert probe.set_mode("OFFBOARD").result == px4.MAV_RESULT_ACCEPTED
        assert probe.arm().result == px4.MAV_RESULT_ACCEPTED
        mark, end_ns = probe.mark(), clock.t_ns + 20 * 10**9
        while v.snapshot().position_ned_m[2] >= -15.0:
            assert clock.t_ns < end_ns, v.snapshot()
            clock.run_for(0.02, send)
        climb = [-m.vz for m in probe.messages("LOCAL_POSITION_NED", after=mark)]
        assert max(climb) <= 3.0 * 1.07  # MPC_Z_VEL_MAX_UP limits the setpoint (PX4 overshoots steps by 3-7 %)
        assert climb[-1] == pytest.approx(3.0, abs=0.1)
        mark, setpoint[0] = probe.mark(), (30.0, 30.0, 0.0)
        clock.run_for(20.0, send)
        speeds = [np.hypot(m.vx, m.vy) for m in probe.messages("LOCAL_POSITION_NED", after=mark)]
        assert len(speeds) > 100
        assert max(speeds) <= 4.0 * 1.05  # MPC_XY_VEL_MAX limits the setpoint
        assert speeds[-1] > 3.5  # the integrator closes most of the drag deficit


def test_ground_does_not_slide_and_platform_start(probe: Probe) -> None:
    with vehicle_for(probe, paced=True, speed=20.0, start_ned=(5.0, -3.0, -0.5)) as v:
        connect(probe)
        snap = v.snapshot()
        assert snap.landed_state == px4.LANDED_ON_GROUND and list(snap.position_ned_m) == [5.0, -3.0, -0.5]
        with start_offboard(probe, (2.0, 0.0, 0.0)) as stream:
            wait_flight(v, lambda s: s.t_s > snap.t_s + 1.0, 2.0, "s.t_s > snap.t_s + 1.0")
            assert list(v.snapshot().position_ned_m) == [5.0, -3.0, -0.5]  # no horizontal slide on the ground
            stream.set(velocity_ned_m_s=(0.0, 0.0, -1.0))
            wait_flight(v, lambda s: s.position_ned_m[2] < -1.0, 2.0, "s.position_ned_m[2] < -1.0")
            stream.set(velocity_ned_m_s=(0.0, 0.0, 1.0))
            # the platform it started on is gone: it lands on the ground, d = 0
            landed = wait_flight(v, lambda s: s.landed_state == px4.LANDED_ON_GROUND, 5.0, "s.landed_state == px4.LANDED_ON_GROUND")
            assert landed is not None and landed.position_ned_m[2] == 0.0


def test_takeoff_hold_and_land_commands(probe: Probe) -> None:
    with vehicle_for(probe, paced=True, speed=20.0, estimate_error=0.0) as v:  # exact: heights to 0.1 m
        connect(probe)
        assert probe.arm().result == px4.MAV_RESULT_ACCEPTED
        assert probe.command(px4.MAV_CMD_NAV_TAKEOFF).result == px4.MAV_RESULT_ACCEPTED
        assert probe.wait_mode("AUTO.TAKEOFF", 2.0)
        held = wait_flight(v, lambda s: s.mode == "AUTO.LOITER" and s.landed_state == px4.LANDED_IN_AIR, 5.0, "s.mode == 'AUTO.LOITER' and s.landed_state == px4.LANDED_IN_AIR")
        assert held is not None
        later = wait_flight(v, lambda s: s.t_s > held.t_s + 2.0, 2.0, "s.t_s > held.t_s + 2.0")
        # MIS_TAKEOFF_ALT, overshot a little: the vertical integrator carries the climb's drag compensation
        assert later is not None and later.position_ned_m[2] == pytest.approx(-2.5, abs=0.1)
        assert probe.command(px4.MAV_CMD_NAV_LAND).result == px4.MAV_RESULT_ACCEPTED
        assert probe.wait_mode("AUTO.LAND", 2.0)
        assert probe.wait_for("EXTENDED_SYS_STATE", lambda m: m.landed_state == px4.LANDED_LANDING, 2.0)
        wait_flight(v, lambda s: not s.armed, 5.0, "not s.armed")


def test_takeoff_to_param7_altitude_amsl(probe: Probe) -> None:
    with vehicle_for(probe, paced=True, speed=20.0, home=(47.0, 8.0, 400.0)) as v:
        connect(probe)
        assert probe.arm().result == px4.MAV_RESULT_ACCEPTED
        ack = probe.command(px4.MAV_CMD_NAV_TAKEOFF, (math.nan,) * 6 + (404.0,))
        assert ack is not None and ack.result == px4.MAV_RESULT_ACCEPTED
        held = wait_flight(v, lambda s: s.mode == "AUTO.LOITER" and s.landed_state == px4.LANDED_IN_AIR, 5.0, "s.mode == 'AUTO.LOITER' and s.landed_state == px4.LANDED_IN_AIR")
        assert held is not None
        wait_flight(v, lambda s: abs(s.position_ned_m[2] + 4.0) < 0.05, 3.0, "abs(s.position_ned_m[2] + 4.0) < 0.05")


def test_return_to_launch_flies_home_and_lands(probe: Probe) -> None:
    with vehicle_for(probe, paced=True, speed=20.0, params={"RTL_RETURN_ALT": 6.0}) as v:
        connect(probe)
        with start_offboard(probe, (4.0, 3.0, -2.0)):
            wait_flight(v, lambda s: s.position_ned_m[0] > 8.0, 5.0, "s.position_ned_m[0] > 8.0")
            assert probe.command(px4.MAV_CMD_NAV_RETURN_TO_LAUNCH).result == px4.MAV_RESULT_ACCEPTED
            assert probe.wait_mode("AUTO.RTL", 2.0)
            climbed = wait_flight(v, lambda s: s.position_ned_m[2] <= -5.9, 5.0, "s.position_ned_m[2] <= -5.9")
            assert climbed is not None
            landed = wait_flight(v, lambda s: s.landed_state == px4.LANDED_ON_GROUND, 10.0, "s.landed_state == px4.LANDED_ON_GROUND")
            assert landed is not None and np.allclose(landed.position_ned_m, [0.0, 0.0, 0.0], atol=0.6)
            wait_flight(v, lambda s: not s.armed, 5.0, "not s.armed")


def test_position_setpoint_and_body_frame_velocity(probe: Probe) -> None:
    with vehicle_for(probe, paced=True, speed=20.0, estimate_error=0.0) as v:  # exact: positions to 0.02 m
        connect(probe)
        with start_offboard(probe, type_mask=setpoints.TYPE_MASK_POSITION, position_ned_m=(3.0, -2.0, -4.0), yaw_rad=math.pi / 2) as s:
            snap = wait_flight(v, lambda x: np.allclose(x.position_ned_m, [3.0, -2.0, -4.0], atol=0.02), 5.0, "np.allclose(x.position_ned_m, [3.0, -2.0, -4.0], atol=0.02)")
            assert snap is not None and snap.yaw_rad == pytest.approx(math.pi / 2, abs=0.01)
            # BODY_NED forward at yaw 90 deg is east
            s.set(velocity_ned_m_s=(1.0, 0.0, 0.0), type_mask=setpoints.TYPE_MASK_VELOCITY_YAW_RATE,
                  frame=px4.MAV_FRAME_BODY_NED, yaw_rate_rad_s=0.0)
            moving = wait_flight(v, lambda x: x.velocity_ned_m_s[1] > 0.99, 3.0, "x.velocity_ned_m_s[1] > 0.99")
            assert moving is not None and abs(moving.velocity_ned_m_s[0]) < 0.02


SCRIPT = ((1.0, (1.5, 0.5, -0.5)), (2.5, (-0.5, 1.0, 0.0)), (3.5, (0.0, 0.0, 0.0)))  # (t since armed [s], velocity NED [m/s])
CLIMB = (0.0, 0.0, -1.5)  # the setpoint before the script [m/s NED]
# Both vehicles wait 30 s of simulated time for a setpoint before PX4's offboard-loss failsafe: at
# speed 10 its 1 s default is 0.1 s of wall time, which a loaded machine (load 7-15) let pass
# between two of the script's setpoints, and the failsafe landed the vehicle (0.36 m flown).
SCRIPT_PARAMS = {"COM_OF_LOSS_T": 30.0}
Velocity = tuple[float, float, float]


def _send_accepted(probe: Probe, v: MockVehicle, velocity: Velocity) -> float:
    """Send one velocity setpoint; wait until the vehicle took it. Returns the simulated time
    [s] it took effect (nobody else sends, so the vehicle's last-setpoint time is this one's)."""
    accepted = v.snapshot().counters["setpoints_accepted"]
    probe.send(probe.setpoint_message(velocity_ned_m_s=velocity))
    return wait_flight(v, lambda s: s.counters["setpoints_accepted"] > accepted, 3.0, "the setpoint taken").last_setpoint_t_s


def _fly_script(speed: float) -> tuple[float, list[tuple[float, Velocity]], np.ndarray]:
    """Fly :data:`SCRIPT` in real time at ``speed``: velocity setpoints every 0.1 s simulated,
    changing at given times since arming, then 1.5 s of rest.

    Returns the arming time [s], every setpoint as (simulated time it took effect, velocity),
    and the final snapshot's (t_s, position NED, velocity NED). When a setpoint takes effect
    depends on the wall clock (at speed 10, a millisecond late is 10 ms of flight); what the
    vehicle does with it must not."""
    with Probe() as probe, vehicle_for(probe, speed=speed, params=dict(SCRIPT_PARAMS)) as v:
        connect(probe)
        with start_offboard(probe, CLIMB, period_s=0.1 / speed):
            t_armed = v.event_time("Armed by external command")
            assert t_armed is not None
            sleep_until(v.clock, t_armed + 0.5)
        changes, velocity, taken = dict(SCRIPT), CLIMB, []
        for k in range(6, 51):
            sleep_until(v.clock, t_armed + 0.1 * k)
            velocity = changes.get(round(0.1 * k, 1), velocity)
            taken.append((_send_accepted(probe, v, velocity), velocity))
        final = v.snapshot()
    return t_armed, taken, np.concatenate(([final.t_s], final.position_ned_m, final.velocity_ned_m_s))


def _replay(t_armed: float, taken: list[tuple[float, Velocity]], t_end: float) -> np.ndarray:
    """The same setpoints at the same simulated times on a vehicle whose clock the test moves
    (no wall clock at all): what simulated time alone prescribes. Returns (t_s, position, velocity)."""
    from mission.time.clock import ManualClock
    from sim.vehicle.mock import VehicleOptions

    clock = ManualClock()
    with Probe() as probe, MockVehicle(VehicleOptions(bind="127.0.0.1:0", target=f"127.0.0.1:{probe.port}",
                                                      params=dict(SCRIPT_PARAMS)), clock=clock) as v:
        probe.vehicle = ("127.0.0.1", v.port)
        connect(probe)

        def at(t_s: float) -> None:  # the vehicle runs whole 5 ms steps up to the clock: half a step past
            clock.advance_to(t_s + PHYSICS_DT_S / 2)
            wait_flight(v, lambda s: s.t_s >= t_s - 1e-9, 3.0, f"the vehicle at t = {t_s} s")

        at(t_armed)
        _send_accepted(probe, v, CLIMB)
        assert probe.set_mode("OFFBOARD").result == px4.MAV_RESULT_ACCEPTED
        assert probe.arm().result == px4.MAV_RESULT_ACCEPTED
        for t_s, velocity in taken:
            at(t_s)
            assert abs(_send_accepted(probe, v, velocity) - t_s) < 1e-9
        at(t_end)
        final = v.snapshot()
    return np.concatenate(([final.t_s], final.position_ned_m, final.velocity_ned_m_s))


def test_speed_factor_10_flies_what_simulated_time_prescribes() -> None:
    """At speed 10 the vehicle flies exactly what simulated time prescribes: the same setpoints,
    taking effect at the same simulated times, on a clock the test moves by hand end in the same
    state (physics, limits and the commander all run on simulated time; only when a setpoint
    arrives depends on the wall clock, and that is replayed)."""
    t_armed, taken, flown = _fly_script(10.0)
    late_s = [t_s - (t_armed + 0.1 * k) for k, (t_s, _) in enumerate(taken, start=6)]
    assert min(late_s) >= -PHYSICS_DT_S  # never before it was sent (the vehicle's 5 ms steps)
    assert np.linalg.norm(flown[1:4]) > 2.5  # it did fly somewhere
    replayed = _replay(t_armed, taken, flown[0])
    assert abs(replayed[0] - flown[0]) < 1e-9
    assert np.allclose(replayed, flown, rtol=0, atol=1e-9), (flown, replayed, max(late_s))


def test_rover_frame_is_a_ground_rover_that_refuses_takeoff_and_drives_offboard(probe: Probe) -> None:
    """In lockstep (the setpoint stream on simulated time: at speed 5 in real time a stream
    stalled 0.1 s of wall under load was a lost stream, and OFFBOARD was refused)."""
    with vehicle_for(probe, frame="rover", lockstep=True) as v:
        clock = Lockstep(probe)
        connect(probe)
        clock.barrier()
        assert probe.latest("HEARTBEAT").type == 10  # MAV_TYPE_GROUND_ROVER
        ack = probe.command(px4.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, 10.0))
        assert ack is not None and ack.result == px4.MAV_RESULT_UNSUPPORTED
        send = lambda: probe.send(probe.setpoint_message((1.0, 0.0, -1.0)))  # noqa: E731
        send()
        assert probe.arm().result == px4.MAV_RESULT_ACCEPTED
        assert probe.set_mode("OFFBOARD").result == px4.MAV_RESULT_ACCEPTED
        heights = []
        clock.run_for(5.0, lambda: (send(), heights.append(v.snapshot().position_ned_m[2])))
        snap = v.snapshot()
        assert snap.mode == "OFFBOARD" and snap.velocity_ned_m_s[0] > 0.9 and snap.position_ned_m[0] > 2.0
        assert max(heights) == 0.0 == min(heights)  # climb commands ignored: on the ground
        assert snap.armed  # no preflight auto-disarm for a rover (armed = not landed)


def test_estimate_error_px4_flies_its_estimate_and_reports_it() -> None:
    """With ``estimate_error`` 1 (PX4 SITL's estimate errors) a position setpoint is held in the
    reported (estimated) frame, whose velocity disagrees with the true one by PX4 SITL's ~0.25 m/s,
    while the true vehicle moves about; without, both agree. In lockstep: the same flight whatever
    the machine's load."""
    target = (2.0, 1.0, -3.0)
    for scale in (1.0, 0.0):
        with Probe() as p, vehicle_for(p, lockstep=True, estimate_error=scale) as v:
            clock = Lockstep(p)
            connect(p)
            clock.barrier()
            send = lambda: p.send(p.setpoint_message(type_mask=setpoints.TYPE_MASK_POSITION, position_ned_m=target))  # noqa: E731
            send()
            assert p.set_mode("OFFBOARD").result == px4.MAV_RESULT_ACCEPTED
            assert p.arm().result == px4.MAV_RESULT_ACCEPTED
            clock.run_for(15.0, send, period_s=0.1)
            reported, true, v_err = [], [], []

            def sample() -> None:
                send()
                lpn, snap = p.latest("LOCAL_POSITION_NED"), v.snapshot()
                reported.append((lpn.x, lpn.y, lpn.z))
                true.append(snap.position_ned_m)
                v_err.append(np.array((lpn.vx, lpn.vy)) - snap.velocity_ned_m_s[:2])

            clock.run_for(30.0, sample, period_s=0.1)
            assert v.snapshot().mode == "OFFBOARD"
        reported_off = np.linalg.norm(np.array(reported) - target, axis=1)
        true_off = np.linalg.norm(np.array(true) - target, axis=1)
        v_rms = float(np.sqrt(np.mean(np.square(v_err))))
        if scale > 0:
            # PX4 alone holds its estimate within decimetres (SITL: 0.4 m RMS); the truth is farther
            # off, and the reported velocity errs by ~0.25 m/s per axis
            assert 0.05 < reported_off.mean() < 0.8 and true_off.mean() > reported_off.mean()
            assert 0.1 < v_rms < 0.5
        else:
            assert reported_off.max() < 0.05 and true_off.max() < 0.05 and v_rms < 0.01


def test_an_injected_clock_is_the_vehicles_time(probe: Probe) -> None:
    """The vehicle flies on the clock it is given: on a ManualClock nothing happens until the
    test moves it (HEARTBEAT at 1 Hz simulated: those of t = 0, 1, 2 s, and no more)."""
    from mission.time.clock import ManualClock, ScaledClock
    from sim.vehicle.mock import VehicleOptions

    clock = ManualClock()
    options = VehicleOptions(bind="127.0.0.1:0", target=f"127.0.0.1:{probe.port}")
    with MockVehicle(options, clock=clock) as v:
        assert probe.wait_for("HEARTBEAT", timeout_s=2.0) is not None and v.snapshot().t_s == 0.0
        for t_s in (1.0, 2.0):
            clock.advance(1.0)
            wait_flight(v, lambda s: s.t_s == t_s, 2.0, f"the vehicle at t = {t_s} s")
            wait_for(lambda: len(probe.messages("HEARTBEAT")) >= t_s + 1, 2.0, f"the HEARTBEAT of t = {t_s} s")
        assert len(probe.messages("HEARTBEAT")) == 3
        assert v.clock is clock
    with pytest.raises(ValueError, match="owns its time"):
        MockVehicle(VehicleOptions(lockstep=True), clock=ScaledClock(1.0))
