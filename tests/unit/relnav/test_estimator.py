"""The relative estimator (mission/relnav): the GNSS-frame bias, the marker, late and out-of-order
measurements, the gate, and a covariance that matches its errors (docs/relnav.md)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mission.config.relnav import RelnavSection
from mission.relnav.estimator import RelativeEstimator
from mission.relnav.inputs import CarrierFix, MarkerFix, OwnSample
from sim.testing.relnav_world import average_nees, fly, make_world

PARAMS = RelnavSection().params()
BIAS = (2.0, 0.0, 0.0)  # [m] the carrier's GNSS frame minus the passenger's
SMOOTH = 0.1  # [m/s^2/sqrt(Hz)] the truth's relative acceleration noise in the bias tests (the filter assumes 0.5)


def _errors(estimates, world, since_s: float) -> np.ndarray:
    """Position errors [m] (estimate minus truth) at the ticks from ``since_s`` on, (n, 3)."""
    return np.array([e.position_ned_m - x[:3] for e, x in zip(estimates, world.truth) if e.t_s >= since_s])


def test_gnss_alone_carries_the_bias():
    """With no marker the bias is not observable: the estimate plus its bias tracks the GNSS
    difference, so its error is the bias less the filter's guess of it, which only the prior
    and the slow drift the model allows shape (here a third of the 2 m); it says so in its
    covariance and is not converged."""
    world = make_world(PARAMS, seed=1, constant_bias_m=BIAS, truth_accel_m_s2=SMOOTH)
    est = fly(RelativeEstimator(PARAMS), world)
    late = [(e, x) for e, x in zip(est, world.truth) if e.t_s >= 20.0]
    err = np.mean([e.position_ned_m - x[:3] for e, x in late], axis=0)
    bias_guess = np.mean([e.bias_ned_m for e, _ in late], axis=0)
    # the error is the bias not guessed (to the GNSS noise the filter averages: 0.16 m measured)
    assert np.allclose(err + bias_guess, BIAS, atol=0.3), (err, bias_guess)
    assert np.linalg.norm(err) > 1.2, err  # most of the 2 m is carried
    last = est[-1]
    assert last.position_sigma_m > 1.5 and not last.converged  # ~ bias_sigma_m
    assert last.since_marker_s == math.inf and last.counts.fused["marker"] == 0


def test_the_marker_removes_the_bias():
    """Markers from 10 s on (3 cm, 50-150 ms late): the bias is estimated and the relative
    position's error falls to a few centimetres in steady state."""
    world = make_world(PARAMS, seed=2, constant_bias_m=BIAS, marker_from_s=10.0, truth_accel_m_s2=SMOOTH)
    est = fly(RelativeEstimator(PARAMS), world)
    before = _errors(est, world, since_s=5.0)[:20].mean(axis=0)
    assert np.linalg.norm(before - BIAS) < 0.3  # GNSS alone: the bias
    steady = _errors(est, world, since_s=20.0)
    assert np.linalg.norm(steady.mean(axis=0)) <= 0.05, steady.mean(axis=0)
    assert np.all(np.sqrt((steady ** 2).mean(axis=0)) <= 0.05)  # RMS per axis
    last = est[-1]
    # the bias is estimated within 3 sigma of its own covariance (0.16 m, 0.24 m down: the GNSS
    # noise against the drift the model allows), the relative position much better (the marker)
    bias_sigma = np.sqrt(np.diag(last.covariance)[6:9])
    assert np.all(np.abs(last.bias_ned_m - BIAS) < 3 * bias_sigma), (last.bias_ned_m, bias_sigma)
    assert np.all(bias_sigma < 0.2 * np.array([1.0, 1.0, PARAMS.vertical_factor])), bias_sigma
    assert last.converged and last.position_sigma_m < PARAMS.converged_sigma_m
    assert last.since_marker_s <= 0.3
    # a 0.999 gate rejects about one good sample in a thousand (here 1 marker of ~300)
    assert last.counts.rejected["marker"] <= 0.01 * last.counts.fused["marker"]
    assert last.counts.rejected["gnss_position"] <= 0.01 * last.counts.fused["gnss_position"]


def test_late_and_out_of_order_measurements_give_the_in_order_result():
    """The same measurements delivered at their capture times, or late (markers 50-150 ms, GNSS
    100-300 ms) and out of order, give the same estimate: each is fused at its capture time."""
    kw = dict(seed=3, constant_bias_m=BIAS, marker_from_s=2.0, duration_s=10.0, measure_until_s=9.0)
    on_time = make_world(PARAMS, marker_delay_s=(0.0, 0.0), gnss_delay_s=(0.0, 0.0), **kw)
    late = make_world(PARAMS, **kw)
    captured = [m.t_s if isinstance(m, CarrierFix) else m.capture_t_s for _, m in late.arrivals]
    assert any(b < a for a, b in zip(captured, captured[1:])), "the late world must deliver out of order"
    a, b = fly(RelativeEstimator(PARAMS), on_time)[-1], fly(RelativeEstimator(PARAMS), late)[-1]
    np.testing.assert_allclose(b.position_ned_m, a.position_ned_m, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.covariance, a.covariance, rtol=0, atol=1e-12)
    assert a.counts == b.counts and a.counts.fused["marker"] > 50


def test_ticks_go_forward_and_are_finite():
    est = RelativeEstimator(PARAMS)
    est.tick(OwnSample(1.0, np.zeros(3), np.zeros(3)))
    with pytest.raises(ValueError, match="not after"):
        est.tick(OwnSample(1.0, np.zeros(3), np.zeros(3)))
    with pytest.raises(ValueError, match="not finite"):
        est.tick(OwnSample(2.0, np.array([0.0, math.nan, 0.0]), np.zeros(3)))
    est.marker(MarkerFix.isotropic(1.5, np.array([math.nan, 0.0, 0.0]), 0.03))  # a NaN measurement is gated
    e = est.tick(OwnSample(2.0, np.zeros(3), np.zeros(3)))
    assert e.counts.rejected["marker"] == 1 and np.all(np.isfinite(e.position_ned_m))


def test_a_measurement_outside_the_history_is_dropped_and_counted():
    est = RelativeEstimator(PARAMS)
    est.marker(MarkerFix.isotropic(0.0, np.zeros(3), 0.03))  # before the first tick
    for k in range(40):
        est.tick(OwnSample(0.05 * k, np.zeros(3), np.zeros(3)))
    est.marker(MarkerFix.isotropic(0.0, np.zeros(3), 0.03))  # 1.95 s late, history 1 s
    est.marker(MarkerFix.isotropic(3.0, np.zeros(3), 0.03))  # 1.05 s ahead of the newest tick
    est.marker(MarkerFix.isotropic(2.5, np.zeros(3), 0.03))  # 0.55 s ahead: waits for a tick to pass it
    counts = est.tick(OwnSample(2.0, np.zeros(3), np.zeros(3))).counts
    assert (counts.too_old, counts.too_new, counts.fused["marker"]) == (2, 1, 0)
    assert est.tick(OwnSample(2.5, np.zeros(3), np.zeros(3))).counts.fused["marker"] == 1


@pytest.mark.parametrize("gated", [True, False])
def test_a_flipped_pose_and_another_tag_are_gated_and_counted(gated: bool):
    """After convergence, 5 flipped poses (the deck mirrored through the vehicle) and 5 detections
    of another tag 0.8 m off are rejected and counted, and the estimate is what it is without them.
    Without the gate (the control) they pull it away: the test can fail."""
    params = PARAMS if gated else dataclasses.replace(PARAMS, gate_nis=1e12)
    world = make_world(params, seed=4, constant_bias_m=BIAS, marker_from_s=5.0, duration_s=25.0, truth_accel_m_s2=SMOOTH)
    truth = {round(o.t_s, 6): x for o, x in zip(world.ticks, world.truth)}
    bad = []
    for i in range(5):
        t = 20.0 + 0.3 * i
        r = truth[round(t, 6)][:3]
        bad.append((t + 0.1, MarkerFix.isotropic(t, np.array([-r[0], -r[1], r[2]]), 0.03)))  # pose flip
        bad.append((t + 0.12, MarkerFix.isotropic(t + 0.05, r + np.array([0.8, 0.0, 0.0]), 0.03)))  # another tag
    est = fly(RelativeEstimator(params), world, extra=bad)
    worst = np.abs(_errors(est, world, since_s=20.0)).max()
    clean = np.abs(_errors(fly(RelativeEstimator(params), world), world, since_s=20.0)).max()
    assert clean < 0.15
    if gated:
        assert est[-1].counts.rejected["marker"] == 10
        np.testing.assert_allclose(est[-1].position_ned_m, fly(RelativeEstimator(params), world)[-1].position_ned_m, atol=1e-9)
    else:
        assert est[-1].counts.rejected["marker"] == 0
        assert worst > 0.3, worst


def _chi2_quantile(p_z: float, dof: int) -> float:
    """The chi-square quantile of ``dof`` degrees of freedom at the standard normal's ``p_z``
    (Wilson-Hilferty; within 0.1 % at these sizes)."""
    a = 2.0 / (9.0 * dof)
    return dof * (1.0 - a + p_z * math.sqrt(a)) ** 3


def test_the_covariance_matches_the_errors_nees():
    """Over 50 seeded runs of the estimator's own model (ticks and GNSS at 10 Hz, markers from 3 s,
    all late), the average normalised estimation error squared of the whole state (9 dof) and
    of the position (3 dof) stays inside the two-sided 99 % chi-square bounds at 5 times."""
    runs = 50
    nees9, nees3 = average_nees(PARAMS, runs)
    for dof, nees in ((9, nees9), (3, nees3)):
        lo, hi = _chi2_quantile(-2.576, dof * runs) / runs, _chi2_quantile(2.576, dof * runs) / runs
        assert np.all((nees > lo) & (nees < hi)), (dof, lo, hi, nees.round(2))


def test_visions_measurement_is_a_marker_observation():
    """vision's ``RelativeMeasurement`` feeds the estimator as it is (skipped where vision is not merged)."""
    vision = pytest.importorskip("mission.vision.measurement")
    est = RelativeEstimator(PARAMS)
    est.tick(OwnSample(0.0, np.zeros(3), np.zeros(3)))
    r = np.array([1.0, -2.0, 3.0])
    est.marker(vision.RelativeMeasurement(
        capture_t_s=0.05, deck_rel_ned_m=r, covariance_ned_m2=np.eye(3) * 1e-4, deck_body_frd_m=r,
        attitude_q_wxyz=np.array([1.0, 0.0, 0.0, 0.0]), deck_yaw_ned_rad=0.0, tag_ids=(0,), reprojection_error_px=0.3,
        marker=vision.MarkerPose(np.eye(3), r)))
    e = est.tick(OwnSample(0.1, np.zeros(3), np.zeros(3)))
    assert e.counts.fused["marker"] == 1 and np.allclose(e.position_ned_m, r, atol=0.01)


@pytest.mark.parametrize("reset", [True, False])
def test_a_run_of_rejected_markers_restarts_the_uncertainty(reset: bool):
    """A carrier at 1.5 m/s that stops dead at 5 s (the lockstep demo's carrier, braking outright
    at its P3 guard: 2 m/s to 0 within 0.1 s): the constant-velocity model runs on, so the
    markers, then the GNSS, fall outside the gate. After ``marker_reset_s`` (0.5 s) of markers
    rejected with none fused, the uncertainty restarts from the prior and the marker is fused
    afresh: from 1 s after the stop the estimate is on the deck again. Without the reset (the
    control: 60 s) every marker is rejected from then on and the estimate runs away."""
    params = PARAMS if reset else dataclasses.replace(PARAMS, marker_reset_s=60.0)
    est = RelativeEstimator(dataclasses.replace(params, accel_noise_m_s2=0.1))  # configs/relnav.toml's steady carrier
    speed, stop_s = np.array([1.5, 0.0, 0.0]), 5.0

    def carrier(t: float) -> tuple[np.ndarray, np.ndarray]:
        return (speed * min(t, stop_s), speed if t < stop_s else np.zeros(3))

    errors = {}
    for k in range(1, 201):  # 10 s at 20 Hz; the vehicle stands at the origin
        t = 0.05 * k
        c, v = carrier(t)
        if k % 2 == 0:
            est.carrier(CarrierFix(t, c, v))  # GNSS, no bias
        est.marker(MarkerFix.isotropic(t, c, 0.01))
        e = est.tick(OwnSample(t, np.zeros(3), np.zeros(3)))
        errors[round(t, 2)] = float(np.linalg.norm(e.position_ned_m - c))
    counts = est.counts()
    assert errors[4.9] < 0.02  # converged on the moving carrier
    assert counts.rejected["marker"] >= 5  # the stop: markers outside the gate
    if reset:
        assert counts.resets >= 1
        assert max(v for t, v in errors.items() if t >= stop_s + 1.0) < 0.05, errors
        assert est.estimate().converged
    else:
        assert counts.resets == 0
        assert errors[10.0] > 1.0, errors[10.0]


@pytest.mark.parametrize("seat_down_m", [0.0, 1.5])
def test_standing_on_the_deck_gives_the_height_too(seat_down_m):
    """The passenger's own GNSS height is 1.6 m off (its estimate reads it 1.6 m up while it stands
    on the deck) and the carrier's GNSS says nothing of it: GNSS alone puts the carrier 1.6 m under
    the vehicle. Standing on its seat (``seat_down_m`` over the carrier's reference point: a hover
    ride's at the reference point's height, a deck ride's on the dock point 1.5 m up), the
    estimate puts the reference point where the seat says, vertically as horizontally, to its
    sigma, and only that sure (an error that stays the same while it stands)."""
    sigma = 0.1
    own = np.array([0.3, -0.2, -1.6 - seat_down_m])  # the vehicle's own estimate: 1.6 m too high
    fix = CarrierFix(0.0, np.zeros(3), np.zeros(3))  # the carrier's GNSS, on its truth
    gnss_only, seated = RelativeEstimator(PARAMS), RelativeEstimator(PARAMS)
    for k in range(100):  # 2 s standing at 50 Hz, GNSS at 10 Hz
        t = 0.02 * k
        for est in (gnss_only, seated):
            if k % 5 == 0:
                est.carrier(dataclasses.replace(fix, t_s=t))
        seated.seated(t, np.array([0.0, 0.0, seat_down_m]), sigma)
        a, b = gnss_only.tick(OwnSample(t, own, np.zeros(3))), seated.tick(OwnSample(t, own, np.zeros(3)))
    assert a.position_ned_m[2] == pytest.approx(1.6 + seat_down_m, abs=0.1)  # GNSS: the carrier too far below
    np.testing.assert_allclose(b.position_ned_m, [0.0, 0.0, seat_down_m], atol=0.05)
    sd = np.sqrt(np.diag(b.covariance)[:3])
    assert np.all(sd >= sigma * 0.99) and np.all(sd <= sigma * 1.3), sd
