"""The paper's law: potential, both branches, carrier command, assumptions (pure)."""
from __future__ import annotations

import numpy as np
import pytest

from mission.errors import AssumptionError, ConfigError
from mission.core.law import LawParams, carrier_command, check_assumptions, norm, passenger_command, potential, project_planar

P = LawParams()


def test_potential_zeros_are_the_three_equilibria():
    L = 20.0
    assert potential(np.array(L), np.array(L), P) == 0  # |e_pc| = |e_tc|
    assert potential(np.array(L / P.b - P.c), np.array(L), P) == pytest.approx(0.0)  # inner zero
    assert potential(np.array(0.0), np.array(L), P) == pytest.approx(P.d * L * (L / P.b - P.c))  # >0 far away


def test_docked_passenger_rides_with_the_carrier_far_from_target():
    u_c = np.array([1.0, -2.0, 0.0])
    cmd = passenger_command(np.zeros(3), np.array([20.0, 0, 0]), u_c, P)
    assert not cmd.leaving
    np.testing.assert_array_equal(cmd.u_p, u_c)


def test_small_offset_is_pulled_back_while_far():
    e_pc = np.array([0.1, 0.0, 0.0])
    cmd = passenger_command(e_pc, np.array([0.0, 20.0, 0]), np.zeros(3), P)
    assert cmd.P > 0 and np.dot(cmd.relative, e_pc) < 0


def test_separating_branch_points_to_target_and_vanishes_at_bc():
    e_tc = np.array([P.b * P.c - 0.01, 0.0])
    cmd = passenger_command(np.zeros(2), e_tc, np.zeros(2), P)
    assert cmd.leaving and np.dot(cmd.relative, e_tc) > 0
    # continuity: at |e_tc| = b c the relative input is exactly zero, and it grows continuously
    at = passenger_command(np.zeros(2), np.array([P.b * P.c, 0.0]), np.zeros(2), P)
    assert norm(at.relative) == 0.0
    eps = np.array([1e-3, 1e-4, 1e-5])
    rel = [norm(passenger_command(np.zeros(2), np.array([P.b * P.c - e, 0.0]), np.zeros(2), P).relative) for e in eps]
    assert rel[0] > rel[1] > rel[2] and rel[2] < 1e-4


def test_batch_and_single_agree():
    rng = np.random.default_rng(0)
    e_pc, e_tc, u_c = rng.normal(size=(3, 50, 3)) * 5
    batch = passenger_command(e_pc, e_tc, u_c, P)
    for i in (0, 17, 49):
        one = passenger_command(e_pc[i], e_tc[i], u_c[i], P)
        np.testing.assert_allclose(one.u_p, batch.u_p[i])


def test_carrier_command_stops_after_separation_and_projects():
    e_tc = np.array([[4.0, 2.0, -3.0], [4.0, 2.0, -3.0]])
    u = carrier_command(e_tc, np.array([True, False]), P, planar=True)
    np.testing.assert_allclose(u[0], [2.0, 1.0, 0.0])
    np.testing.assert_array_equal(u[1], 0.0)
    assert project_planar(np.array([1.0, 2.0]))[1] == 2.0


@pytest.mark.parametrize("field,kwargs", [("law.b", {"b": 1.0}), ("law.c", {"c": 0.0}), ("law.k_p", {"k_p": -1}),
                                          ("law.d", {"d": float("nan")}), ("law.k_c", {"k_c": float("inf")})])
def test_bad_parameters_name_the_field(field, kwargs):
    with pytest.raises(ConfigError) as exc:
        LawParams(**kwargs)
    assert exc.value.field == field and field in str(exc.value)


def test_assumption_bc_below_eta():
    with pytest.raises(AssumptionError, match="b\\*c = 8"):
        check_assumptions(np.zeros(2), np.array([7.0, 0.0]), P)
    with pytest.raises(AssumptionError, match="eta"):
        check_assumptions(np.zeros(2), np.array([20.0, 0.0]), P, eta=25.0)


def test_assumption_passenger_on_carrier():
    with pytest.raises(AssumptionError, match="passenger_start"):
        check_assumptions(np.zeros(2), np.array([20.0, 0.0]), P, passenger_start=np.array([0.5, 0.0]), dock_tolerance_m=0.1)


def test_assumption_target_height_for_planar_carrier():
    with pytest.raises(AssumptionError, match="height 9.000 m"):
        check_assumptions(np.zeros(3), np.array([30.0, 0.0, -9.0]), P, planar_carrier=True)
    check_assumptions(np.zeros(3), np.array([30.0, 0.0, -8.0]), P, planar_carrier=True)
