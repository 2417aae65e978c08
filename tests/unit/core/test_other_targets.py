"""A carrier on a mission with several targets steers round the other legs' targets (pure): its
CBF rows keep it ``b c`` from them, so its P3 guards never have to brake it there."""
from __future__ import annotations

import math

import numpy as np

from mission.carrier.controller import carrier_model, guard_params
from mission.carrier.guard import P3Guard
from mission.config.schema import load_config
from mission.core.tick import carrier_tick, target_keep_outs
from tests.conftest import CONFIGS


def test_keep_outs_are_the_targets_discs_in_the_carrier_s_plane() -> None:
    obs = target_keep_outs([np.array([10.0, 0.0, -5.0]), np.array([0.0, 0.0, -9.0])], 8.0, True, 0.0)
    assert obs.centers.tolist() == [[10.0, 0.0]]  # the second is higher above the plane than 8 m
    assert obs.radii[0] == math.sqrt(64.0 - 25.0)
    assert target_keep_outs([np.array([1.0, 2.0])], 8.0, True).radii.tolist() == [8.0]


def test_a_carrier_riding_to_target_2_past_target_1_steers_round_it_without_its_guard() -> None:
    """configs/cycle.toml's leg 2, from the far side of target 1 (where a recovery course can
    leave it): the law drives straight through target 1's circle; the filtered command goes round,
    target 1's guard never cuts it, and it changes at no more than the carrier's acceleration limit."""
    cfg = load_config(CONFIGS / "cycle.toml")
    t1, t2 = (np.asarray(t, dtype=float) for t in cfg.scenario.legs())
    model = carrier_model(cfg, target=t2)
    guard = P3Guard(guard_params(cfg), t1)  # (its own target's guard slows it near separation, as it should)
    x = t1 + 12.0 * (t1 - t2) / float(np.linalg.norm(t1 - t2))  # behind target 1, on the line to target 2
    x[1] += 0.5
    x[2] = 0.0
    u, dt = np.zeros(3), 1.0 / cfg.carrier.rate_hz
    accel = cfg.safety.carrier_max_accel_m_s2
    closest, largest_step = math.inf, 0.0
    for k in range(int(60.0 / dt)):
        res = carrier_tick(x, False, model, u_prev=u, dt_s=dt)
        new = np.asarray(res.u, dtype=float)
        assert not guard.limit(k * dt, x, new, u).active, (k, x)
        largest_step = max(largest_step, float(np.linalg.norm(new - u)))
        u = new
        x = x + u * dt
        closest = min(closest, float(np.linalg.norm(t1 - x)))
        if float(np.linalg.norm(t2 - x)) <= model.law.separation_distance_m:
            break
    assert float(np.linalg.norm(t2 - x)) <= model.law.separation_distance_m + 0.01, x  # it got there
    assert closest >= model.law.separation_distance_m, closest
    # no brake: the barrier turns the command at about the acceleration limit (it has the last
    # word over that limit: 1.54 m/s^2 at its steepest here, against 1 m/s^2)
    assert largest_step <= accel * dt * 2.0, largest_step


def test_a_leg_begun_at_the_last_target_s_guard_circle_is_not_pushed_out() -> None:
    """configs/cycle.toml's leg 2 begun where leg 1 left the carrier: at rest on target 1's guard
    circle (b c - carrier.p3_margin_m), inside target 1's keep-out (b c + safety.margin_m). The
    barrier holds it there (no deeper) and never pushes it out: its command grows from rest at its
    acceleration limit, and it never comes closer to target 1 than it began (Monte-Carlo scenario
    #102 of seed 1: pushed out at 1.2 m/s in a tick, the riding passenger 0.56 m off its dock)."""
    cfg = load_config(CONFIGS / "cycle.toml")
    t1, t2 = (np.asarray(t, dtype=float) for t in cfg.scenario.legs())
    model = carrier_model(cfg, target=t2)
    g = guard_params(cfg)
    height = float(t1[2])
    # on target 1's guard circle, on the side away from target 2's line (the law leads past target 1)
    side = np.array([-0.6, 0.8, 0.0])
    x = t1 + math.sqrt(g.radius_m ** 2 - height ** 2) * side
    x[2] = 0.0
    start = float(np.linalg.norm(t1 - x))
    u, dt = np.zeros(3), 1.0 / cfg.carrier.rate_hz
    accel = cfg.safety.carrier_max_accel_m_s2
    closest, largest_step = math.inf, 0.0
    for _ in range(int(20.0 / dt)):
        new = np.asarray(carrier_tick(x, False, model, u_prev=u, dt_s=dt).u, dtype=float)
        largest_step = max(largest_step, float(np.linalg.norm(new - u)))
        u = new
        x = x + u * dt
        closest = min(closest, float(np.linalg.norm(t1 - x)))
    assert largest_step <= accel * dt + 1e-9, largest_step  # a push out would be ~1.2 m/s in a tick
    assert closest >= start - 1e-3, (closest, start)
    assert float(np.linalg.norm(t2 - x)) < float(np.linalg.norm(t2 - (t1 + math.sqrt(g.radius_m ** 2 - height ** 2) * side))) - 5.0


def test_the_batch_path_holds_a_carrier_inside_another_keep_out_as_one_state_does() -> None:
    """configs/cycle.toml's leg 2 for a batch of carriers (``sim/batch/closed_loop.py``'s path,
    states (B, 3)) beside the same carriers one at a time (the flight's path, (3,)): two begun
    inside target 1's keep-out (on its guard circle, and deeper), one outside every keep-out. Tick
    for tick for 10 s the batch's commands are the single states' (the keep-outs shrunk per
    carrier, :func:`keep_outs_at`), and neither carrier inside is pushed out."""
    cfg = load_config(CONFIGS / "cycle.toml")
    t1, t2 = (np.asarray(t, dtype=float) for t in cfg.scenario.legs())
    model = carrier_model(cfg, target=t2)
    g = guard_params(cfg)
    height = float(t1[2])
    on_circle = math.sqrt(g.radius_m ** 2 - height ** 2)
    x = np.array([t1 + on_circle * np.array([-0.6, 0.8, 0.0]), t1 + (on_circle - 1.0) * np.array([0.0, -1.0, 0.0]),
                  t1 + 3.0 * on_circle * np.array([-0.6, 0.8, 0.0])])
    x[:, 2] = 0.0
    others = model.other_keep_outs
    assert others is not None
    depth = float(np.linalg.norm(x[0, :2] - others.centers[0]))
    assert depth < others.radii[0] + cfg.safety.margin_m  # inside target 1's keep-out: the shrink is at stake
    singles = [row.copy() for row in x]
    u, u1 = np.zeros_like(x), [np.zeros(3) for _ in x]
    dt = 1.0 / cfg.carrier.rate_hz
    start = np.linalg.norm(x[:2, :2] - t1[:2], axis=1)
    closest = start.copy()
    for _ in range(int(10.0 / dt)):
        u = np.asarray(carrier_tick(x, False, model, u_prev=u, dt_s=dt).u, dtype=float)
        for i in range(len(singles)):
            u1[i] = np.asarray(carrier_tick(singles[i], False, model, u_prev=u1[i], dt_s=dt).u, dtype=float)
            singles[i] = singles[i] + u1[i] * dt
        np.testing.assert_allclose(u, np.array(u1), rtol=0.0, atol=1e-12)
        x = x + u * dt
        closest = np.minimum(closest, np.linalg.norm(x[:2, :2] - t1[:2], axis=1))
    assert (closest >= start - 1e-3).all(), (closest, start)


def test_a_carrier_driving_into_another_keep_out_brakes_at_its_limit_not_in_one_step() -> None:
    """A team's hand-over: the carrier at the edge of the target it just served (now another
    target's keep-out for the next leg), driving straight at it at 1.6 m/s. The shrink leaves its
    row asking the inward speed to fall by at most the acceleration limit a step (before: 1.6 ->
    0.03 m/s in one step under the next riding passenger); it stops, and from rest it is held
    where it stands as before."""
    cfg = load_config(CONFIGS / "cycle.toml")
    t1, t2 = (np.asarray(t, dtype=float) for t in cfg.scenario.legs())
    model = carrier_model(cfg, target=t2)
    others = model.other_keep_outs
    assert others is not None
    a_max = model.carrier_safety.max_accel_m_s2
    assert a_max is not None
    dt = 1.0 / cfg.carrier.rate_hz
    centre = np.array([*others.centers[0][:2], 0.0])
    edge = float(others.radii[0]) + cfg.safety.margin_m
    inward = np.array([1.0, 0.0, 0.0])
    x = centre - (edge + 0.01) * inward
    u = 1.6 * inward
    dist = []
    for _ in range(int(4.0 / dt)):
        nxt = np.asarray(carrier_tick(x, False, model, u_prev=u, dt_s=dt).u, dtype=float)
        radial = (centre - x) / float(np.linalg.norm(centre - x))
        assert float(np.dot(u - nxt, radial)) <= a_max * dt + 1e-9, (u, nxt)  # the inward speed falls at the limit
        assert float(np.linalg.norm(nxt - u)) <= 1.5 * a_max * dt, (u, nxt)  # the law's turn adds a little
        u = nxt
        x = x + u * dt
        dist.append(float(np.linalg.norm(x[:2] - centre[:2])))
    assert min(dist) >= edge - 1.6 ** 2 / (2 * a_max) - 0.1, min(dist)  # braked at the limit, no more
    last = np.array(dist[-int(1.0 / dt):])
    assert (np.diff(last) >= -1e-3 * dt).all(), last  # stopped going in: it slides round, towards its target
