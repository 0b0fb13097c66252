"""Tests of LFOP and LFOPC (Snyman 1983, 2000) on problems with hand-calculated optima."""

import numpy as np
import pytest

from suspension_tuning.optim.lfopc import LfopOptions, lfop, lfopc


def _quadratic_objective(x):
    # f = (x1 - 2)^2 + (x2 - 1)^2, unconstrained minimum (2, 1).
    return (x[0] - 2.0) ** 2 + (x[1] - 1.0) ** 2


def _quadratic_gradient(x):
    return np.array([2.0 * (x[0] - 2.0), 2.0 * (x[1] - 1.0)])


def test_lfop_finds_minimum_of_ill_conditioned_quadratic():
    # F = x1^2 + 10 x2^2 has its minimum at the origin (gradient (2 x1, 20 x2) = 0).
    result = lfop(lambda x: np.array([2.0 * x[0], 20.0 * x[1]]), [3.0, 1.0])
    assert result.converged
    # The gradient test ||grad F|| <= 1e-5 bounds |x1| <= 5e-6 and |x2| <= 5e-7.
    np.testing.assert_allclose(result.x, [0.0, 0.0], atol=1e-5)
    assert result.grad_norm <= 1e-5


def test_lfop_solves_rosenbrock_from_standard_start():
    # Rosenbrock 100 (x2 - x1^2)^2 + (1 - x1)^2 has its only minimum at (1, 1);
    # (-1.2, 1) is the standard start (More, Garbow and Hillstrom 1981).
    def grad(x):
        return np.array(
            [-400.0 * x[0] * (x[1] - x[0] ** 2) - 2.0 * (1.0 - x[0]), 200.0 * (x[1] - x[0] ** 2)]
        )

    result = lfop(grad, [-1.2, 1.0])
    assert result.converged
    # Tolerance 1e-4: the gradient test 1e-5 over the smallest Hessian eigenvalue
    # at (1, 1) (about 0.4) bounds the error near 2.5e-5.
    np.testing.assert_allclose(result.x, [1.0, 1.0], atol=1e-4)


def test_lfop_converges_on_stiff_penalty_wall():
    # P = (x1-2)^2 + (x2-1)^2 + mu max(0, x1 + x2 - 2)^2 with mu = 1e4 (LFOPC phase 1).
    # By hand: x = (2 - t, 1 - t), dP/dt = 4t - 4 mu (1 - 2t) = 0 gives
    # t = mu / (1 + 2 mu) = 0.4999750, x* = (1.5000250, 0.5000250).  Without the stability
    # safeguard this run cycled between the wall and the interior and hit its step cap.
    mu = 1e4

    def grad(x):
        g = max(x[0] + x[1] - 2.0, 0.0)
        return _quadratic_gradient(x) + 2.0 * mu * g * np.array([1.0, 1.0])

    result = lfop(grad, [1.5025, 0.5025], {'max_steps': 3000})
    assert result.converged
    t = mu / (1.0 + 2.0 * mu)
    # Gradient test 1e-5 over the smallest curvature 2 bounds the error by 5e-6.
    np.testing.assert_allclose(result.x, [2.0 - t, 1.0 - t], atol=5e-6)


def test_lfopc_active_linear_inequality_reaches_kkt_point():
    # min (x1-2)^2 + (x2-1)^2 s.t. x1 + x2 - 2 <= 0.  KKT by hand: x1 - 2 = x2 - 1
    # and x1 + x2 = 2 give x* = (1.5, 0.5), multiplier 1, f* = 0.5.
    result = lfopc(
        _quadratic_objective,
        _quadratic_gradient,
        [0.0, 0.0],
        g=lambda x: np.array([x[0] + x[1] - 2.0]),
        jac_g=lambda x: np.array([[1.0, 1.0]]),
    )
    assert result.success
    np.testing.assert_array_equal(result.active, [0])
    np.testing.assert_allclose(result.x, [1.5, 0.5], atol=1e-5)
    assert result.f == pytest.approx(0.5, rel=1e-5)
    # Phase 2 puts x on the active constraint, far closer than the phase-1
    # penalty offset (multiplier / (2 mu1) / ||grad g||, about 3.5e-5).
    assert abs(result.g[0]) < 1e-6
    assert result.max_violation < 1e-6


def test_lfopc_inactive_constraint_leaves_unconstrained_minimum():
    # x1 + x2 <= 5 is inactive at the unconstrained minimum (2, 1) (2 + 1 < 5).
    result = lfopc(
        _quadratic_objective,
        _quadratic_gradient,
        [0.0, 0.0],
        g=lambda x: np.array([x[0] + x[1] - 5.0]),
        jac_g=lambda x: np.array([[1.0, 1.0]]),
    )
    assert result.success
    assert result.active.size == 0
    assert result.nsteps[2] == 0  # no phase 2 without active constraints or equalities
    np.testing.assert_allclose(result.x, [2.0, 1.0], atol=1e-5)


def test_lfopc_equality_constraint():
    # min x1^2 + x2^2 s.t. x1 + x2 - 1 = 0: by symmetry and KKT x* = (0.5, 0.5).
    result = lfopc(
        lambda x: float(x @ x),
        lambda x: 2.0 * x,
        [2.0, -3.0],
        h=lambda x: np.array([x[0] + x[1] - 1.0]),
        jac_h=lambda x: np.array([[1.0, 1.0]]),
    )
    assert result.success
    np.testing.assert_allclose(result.x, [0.5, 0.5], atol=1e-5)
    assert abs(result.h[0]) < 1e-6


def test_lfopc_nonlinear_constraint_from_infeasible_start():
    # min -x1 - x2 s.t. x1^2 + x2^2 - 1 <= 0: the optimum is on the unit circle in
    # the direction (1, 1), x* = (1/sqrt 2, 1/sqrt 2), f* = -sqrt 2.  Start (3, 2)
    # violates the constraint (g = 12).
    result = lfopc(
        lambda x: -x[0] - x[1],
        lambda x: np.array([-1.0, -1.0]),
        [3.0, 2.0],
        g=lambda x: np.array([x @ x - 1.0]),
        jac_g=lambda x: (2.0 * x)[None, :],
    )
    assert result.success
    np.testing.assert_allclose(result.x, [2**-0.5, 2**-0.5], atol=1e-5)
    assert result.f == pytest.approx(-(2**0.5), rel=1e-5)


def test_lfopc_two_active_constraints_meet_at_vertex():
    # min -x1 - 2 x2 s.t. x1 + x2 <= 1, -x1 <= 0 (x1 >= 0): linear objective, the
    # optimum is the vertex (0, 1) where both constraints are active, f* = -2.
    result = lfopc(
        lambda x: -x[0] - 2.0 * x[1],
        lambda x: np.array([-1.0, -2.0]),
        [0.2, 0.2],
        g=lambda x: np.array([x[0] + x[1] - 1.0, -x[0]]),
        jac_g=lambda x: np.array([[1.0, 1.0], [-1.0, 0.0]]),
    )
    assert result.success
    np.testing.assert_array_equal(result.active, [0, 1])
    np.testing.assert_allclose(result.x, [0.0, 1.0], atol=1e-5)


def test_lfop_options_reject_bad_values():
    with pytest.raises(ValueError, match='unknown LFOP option'):
        LfopOptions.from_mapping({'time_step': 0.5})
    with pytest.raises(ValueError, match='dt'):
        LfopOptions(dt=-1.0)
    with pytest.raises(ValueError, match='mu1 >= mu0'):
        LfopOptions(mu0=1e4, mu1=1e2)


def test_lfopc_rejects_nan_start_and_half_given_constraints():
    with pytest.raises(ValueError, match='finite'):
        lfopc(_quadratic_objective, _quadratic_gradient, [np.nan, 0.0])
    with pytest.raises(ValueError, match='Jacobian'):
        lfopc(_quadratic_objective, _quadratic_gradient, [0.0, 0.0], g=lambda x: x)
