"""Tests of Dynamic-Q (Snyman and Hay 2002) on analytic problems with published optima.

Optima: Hock and Schittkowski (1981), "Test examples for nonlinear programming codes",
Lecture Notes in Economics and Mathematical Systems 187 (HS21, HS35, HS71, HS6, HS7);
the others are hand calculations written beside them.  Accuracy asked by the issue:
1e-4 relative (on x, with max(1, |x*|) as the scale, and on f; absolute where f* = 0).
"""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from suspension_tuning.optim import (
    DynamicQ,
    DynamicQOptions,
    LfopOptions,
    dynamic_q,
    load_options,
    minimize,
)

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'optimiser.yaml'
REL = 1e-4  # the accuracy requirement


def _rosen(x):
    return 100.0 * (x[1] - x[0] ** 2) ** 2 + (1.0 - x[0]) ** 2


def _rosen_grad(x):
    return np.array(
        [-400.0 * x[0] * (x[1] - x[0] ** 2) - 2.0 * (1.0 - x[0]), 200.0 * (x[1] - x[0] ** 2)]
    )


def hs21():
    # HS21: min 0.01 x1^2 + x2^2 - 100 s.t. 10 x1 - x2 - 10 >= 0, 2 <= x1 <= 50,
    # -50 <= x2 <= 50.  x* = (2, 0), f* = -99.96 (HS 1981).  HS's start (-1, -1) lies
    # outside the bounds; (2, -1) is it moved onto the bound x1 = 2.
    return dict(
        fun=lambda x: 0.01 * x[0] ** 2 + x[1] ** 2 - 100.0,
        jac=lambda x: np.array([0.02 * x[0], 2.0 * x[1]]),
        x0=[2.0, -1.0],
        bounds=[(2.0, 50.0), (-50.0, 50.0)],
        constraints=[
            {
                'type': 'ineq',
                'fun': lambda x: 10.0 * x[0] - x[1] - 10.0,
                'jac': lambda x: np.array([10.0, -1.0]),
            }
        ],
        x_star=[2.0, 0.0],
        f_star=-99.96,
    )


def hs35():
    # HS35 (Beale): min 9 - 8x1 - 6x2 - 4x3 + 2x1^2 + 2x2^2 + x3^2 + 2x1x2 + 2x1x3
    # s.t. 3 - x1 - x2 - 2 x3 >= 0, x >= 0; start (0.5, 0.5, 0.5).
    # x* = (4/3, 7/9, 4/9), f* = 1/9 (HS 1981).
    return dict(
        fun=lambda x: (
            9.0
            - 8.0 * x[0]
            - 6.0 * x[1]
            - 4.0 * x[2]
            + 2.0 * x[0] ** 2
            + 2.0 * x[1] ** 2
            + x[2] ** 2
            + 2.0 * x[0] * x[1]
            + 2.0 * x[0] * x[2]
        ),
        jac=lambda x: np.array(
            [
                -8.0 + 4.0 * x[0] + 2.0 * x[1] + 2.0 * x[2],
                -6.0 + 4.0 * x[1] + 2.0 * x[0],
                -4.0 + 2.0 * x[2] + 2.0 * x[0],
            ]
        ),
        x0=[0.5, 0.5, 0.5],
        bounds=[(0.0, None)] * 3,
        constraints=[
            {
                'type': 'ineq',
                'fun': lambda x: 3.0 - x[0] - x[1] - 2.0 * x[2],
                'jac': lambda x: np.array([-1.0, -1.0, -2.0]),
            }
        ],
        x_star=[4.0 / 3.0, 7.0 / 9.0, 4.0 / 9.0],
        f_star=1.0 / 9.0,
    )


def hs71():
    # HS71: min x1 x4 (x1 + x2 + x3) + x3 s.t. x1 x2 x3 x4 >= 25, sum x_i^2 = 40,
    # 1 <= x <= 5; start (1, 5, 5, 1) (violates the equality: sum x^2 = 52).
    # x* = (1, 4.7429994, 3.8211503, 1.3794082), f* = 17.0140173 (HS 1981).
    return dict(
        fun=lambda x: x[0] * x[3] * (x[0] + x[1] + x[2]) + x[2],
        jac=lambda x: np.array(
            [
                x[3] * (2.0 * x[0] + x[1] + x[2]),
                x[0] * x[3],
                x[0] * x[3] + 1.0,
                x[0] * (x[0] + x[1] + x[2]),
            ]
        ),
        x0=[1.0, 5.0, 5.0, 1.0],
        bounds=[(1.0, 5.0)] * 4,
        constraints=[
            {
                'type': 'ineq',
                'fun': lambda x: x[0] * x[1] * x[2] * x[3] - 25.0,
                'jac': lambda x: np.array(
                    [
                        x[1] * x[2] * x[3],
                        x[0] * x[2] * x[3],
                        x[0] * x[1] * x[3],
                        x[0] * x[1] * x[2],
                    ]
                ),
            },
            {'type': 'eq', 'fun': lambda x: x @ x - 40.0, 'jac': lambda x: 2.0 * x},
        ],
        x_star=[1.0, 4.7429994, 3.8211503, 1.3794082],
        f_star=17.0140173,
    )


def hs6():
    # HS6: min (1 - x1)^2 s.t. 10 (x2 - x1^2) = 0; start (-1.2, 1).  x* = (1, 1), f* = 0.
    return dict(
        fun=lambda x: (1.0 - x[0]) ** 2,
        jac=lambda x: np.array([-2.0 * (1.0 - x[0]), 0.0]),
        x0=[-1.2, 1.0],
        bounds=None,
        constraints=[
            {
                'type': 'eq',
                'fun': lambda x: 10.0 * (x[1] - x[0] ** 2),
                'jac': lambda x: np.array([-20.0 * x[0], 10.0]),
            }
        ],
        x_star=[1.0, 1.0],
        f_star=0.0,
    )


def hs7():
    # HS7: min ln(1 + x1^2) - x2 s.t. (1 + x1^2)^2 + x2^2 - 4 = 0; start (2, 2).
    # x* = (0, sqrt 3), f* = -sqrt 3 (HS 1981).
    return dict(
        fun=lambda x: math.log(1.0 + x[0] ** 2) - x[1],
        jac=lambda x: np.array([2.0 * x[0] / (1.0 + x[0] ** 2), -1.0]),
        x0=[2.0, 2.0],
        bounds=None,
        constraints=[
            {
                'type': 'eq',
                'fun': lambda x: (1.0 + x[0] ** 2) ** 2 + x[1] ** 2 - 4.0,
                'jac': lambda x: np.array([4.0 * x[0] * (1.0 + x[0] ** 2), 2.0 * x[1]]),
            }
        ],
        x_star=[0.0, math.sqrt(3.0)],
        f_star=-math.sqrt(3.0),
    )


def rosenbrock_bound_active():
    # Rosenbrock in [-2, 0.5] x [-2, 2] from (-1.2, 1).  Hand calculation: along the
    # valley x2 = x1^2, f = (1 - x1)^2 falls until x1 = 1, so the bound x1 = 0.5 is
    # active; then x2 = 0.25 (df/dx2 = 0) and df/dx1 = -1 < 0 there (KKT with the
    # upper bound).  x* = (0.5, 0.25), f* = 0.25.
    return dict(
        fun=_rosen,
        jac=_rosen_grad,
        x0=[-1.2, 1.0],
        bounds=[(-2.0, 0.5), (-2.0, 2.0)],
        constraints=[],
        x_star=[0.5, 0.25],
        f_star=0.25,
    )


def rosenbrock_interior():
    # Rosenbrock in [-2, 2]^2 from (-1.2, 1): the bounds are inactive, x* = (1, 1),
    # f* = 0.  Tolerances: the step test bounds the error only by about xtol times the
    # condition number of the Hessian at x* (about 2500), so xtol = 1e-8 for 1e-4 on x
    # (with the default 1e-5 the run stops at error 2.5e-3, f = 1.5e-6); near f* = 0
    # the ftol test is absolute, and f - f* = 1e-9 still allows an error of 7e-5 along
    # the valley (smallest Hessian eigenvalue 0.4), hence ftol = 1e-12.
    return dict(
        fun=_rosen,
        jac=_rosen_grad,
        x0=[-1.2, 1.0],
        bounds=[(-2.0, 2.0), (-2.0, 2.0)],
        constraints=[],
        x_star=[1.0, 1.0],
        f_star=0.0,
        options={'xtol': 1e-8, 'ftol': 1e-12},
    )


def constrained_quadratic():
    # min ||x - p||^2 with p = (1, 2, 3) s.t. x1 + x2 + x3 <= 3.  Closed form (projection
    # onto the half-space): x* = p - (a.p - 3)/||a||^2 a = p - (6 - 3)/3 (1, 1, 1)
    # = (0, 1, 2), f* = 3.
    p = np.array([1.0, 2.0, 3.0])
    return dict(
        fun=lambda x: float((x - p) @ (x - p)),
        jac=lambda x: 2.0 * (x - p),
        x0=[0.0, 0.0, 0.0],
        bounds=None,
        constraints=[
            {'type': 'ineq', 'fun': lambda x: 3.0 - x.sum(), 'jac': lambda x: -np.ones(3)}
        ],
        x_star=[0.0, 1.0, 2.0],
        f_star=3.0,
    )


PROBLEMS = {
    'hs21': hs21,
    'hs35': hs35,
    'hs71': hs71,
    'hs6': hs6,
    'hs7': hs7,
    'rosenbrock_bound_active': rosenbrock_bound_active,
    'rosenbrock_interior': rosenbrock_interior,
    'constrained_quadratic': constrained_quadratic,
}


def _solve(problem, **overrides):
    kwargs = dict(
        jac=problem['jac'],
        bounds=problem['bounds'],
        constraints=problem['constraints'],
        options=problem.get('options'),
    )
    kwargs.update(overrides)
    return minimize(problem['fun'], problem['x0'], **kwargs)


def _assert_at_optimum(result, problem):
    x_star = np.asarray(problem['x_star'])
    error = np.abs(result.x - x_star) / np.maximum(1.0, np.abs(x_star))
    assert np.all(error <= REL), f'x = {result.x}, x* = {x_star}, error {error}'
    f_star = problem['f_star']
    assert abs(result.fun - f_star) <= REL * max(1.0, abs(f_star)), result.fun
    assert result.max_violation <= 1e-6  # gtol, the default feasibility tolerance


@pytest.mark.parametrize('name', list(PROBLEMS))
def test_minimize_reaches_published_optimum(name, record_property):
    problem = PROBLEMS[name]()
    result = _solve(problem)
    assert result.success, result.message
    _assert_at_optimum(result, problem)
    # One (f, g, h) evaluation per iteration plus the start; one gradient per iteration.
    assert result.nfev == result.nit + 1
    assert result.ngev == result.nit
    assert result.ngev_by_source == {'analytic': result.nit}
    assert result.nfev_fd == 0
    record_property('counts', f'nit={result.nit} nfev={result.nfev} ngev={result.ngev}')
    print(f'{name}: nit={result.nit} nfev={result.nfev} ngev={result.ngev} f={result.fun:.10g}')


def test_central_differences_when_no_jacobian_given():
    # HS35 without any jac: central differences (2n = 6 calls per gradient of f and of
    # the constraint) reach the same optimum; counts are kept apart.
    problem = hs35()
    constraints = [{'type': c['type'], 'fun': c['fun']} for c in problem['constraints']]
    result = _solve(problem, jac=None, constraints=constraints)
    assert result.success
    _assert_at_optimum(result, problem)
    assert result.ngev_by_source == {'central_difference': result.nit}
    assert result.nfev_fd == 6 * result.nit  # 2n objective calls per gradient, n = 3
    assert result.ncev_fd == 6 * result.nit  # and 2n calls of the constraint function


def test_paper_convention_counts_gradient_source_by_name():
    # The constrained quadratic in paper convention: g = x1 + x2 + x3 - 3 <= 0.
    p = np.array([1.0, 2.0, 3.0])

    def evaluate(x):
        return float((x - p) @ (x - p)), np.array([x.sum() - 3.0]), None

    def gradient(x):
        return 2.0 * (x - p), np.ones((1, 3)), None

    gradient.source = 'simplified'
    result = dynamic_q(evaluate, gradient, [0.0, 0.0, 0.0], options={'rho0': 0.9})
    assert result.success
    np.testing.assert_allclose(result.x, [0.0, 1.0, 2.0], atol=REL)  # closed form above
    assert result.ngev_by_source == {'simplified': result.nit}
    assert result.g.shape == (1,) and result.h.shape == (0,)
    first = result.history[0]
    assert first['iteration'] == 0 and first['rho'] == 0.0
    assert [rec['iteration'] for rec in result.history] == list(range(result.nit + 1))
    assert result.history[1]['curvature']['a'] == 0.0  # first subproblem: zero curvature [R]
    # Second iteration: the curvature interpolates the previous point, exactly 2 for f
    # (f = ||x - p||^2 has Hessian 2 I) and 0 for the linear constraint.
    assert result.history[2]['curvature']['a'] == pytest.approx(2.0, rel=1e-9)
    assert result.history[2]['curvature']['b'][0] == pytest.approx(0.0, abs=1e-9)


def test_infeasible_start_reaches_feasible_optimum():
    # Constrained quadratic from (5, 5, 5): x1 + x2 + x3 = 15 > 3 violates the constraint
    # by 12; the optimum is (0, 1, 2), f* = 3 (closed form above).
    problem = constrained_quadratic()
    problem['x0'] = [5.0, 5.0, 5.0]
    result = _solve(problem)
    assert result.history[0]['max_violation'] == pytest.approx(12.0)
    assert result.success
    _assert_at_optimum(result, problem)


@pytest.mark.parametrize('name', ['hs21', 'hs71', 'rosenbrock_bound_active'])
@pytest.mark.parametrize('jac', ['analytic', 'central_difference'])
def test_never_evaluates_outside_bounds(name, jac):
    problem = PROBLEMS[name]()
    lower = np.array([b[0] for b in problem['bounds']], dtype=float)
    upper = np.array([b[1] for b in problem['bounds']], dtype=float)
    calls = []

    def guarded(x):
        calls.append(np.copy(x))
        assert np.all(x >= lower) and np.all(x <= upper), f'f asked outside bounds at {x}'
        return problem['fun'](x)

    result = _solve(problem, jac=problem['jac'] if jac == 'analytic' else None)
    result_guarded = minimize(
        guarded,
        problem['x0'],
        jac=problem['jac'] if jac == 'analytic' else None,
        bounds=problem['bounds'],
        constraints=problem['constraints'],
    )
    assert len(calls) == result_guarded.nfev + result_guarded.nfev_fd
    np.testing.assert_array_equal(result_guarded.x, result.x)  # deterministic
    # The bounded problems end on a bound: x1 = 2 (HS21), x1 = 1 (HS71), x1 = 0.5.
    assert np.min(np.minimum(result.x - lower, upper - result.x)) <= 1e-6


def test_callback_sees_every_iteration():
    problem = hs71()
    seen = []

    def callback(intermediate_result):
        seen.append(intermediate_result)

    result = _solve(problem, callback=callback)
    assert [r.nit for r in seen] == list(range(1, result.nit + 1))
    for rec in seen:
        np.testing.assert_array_equal(rec.x, result.history[rec.nit]['x'])
        assert rec.fun == result.history[rec.nit]['f']
        assert rec.rho > 0 and rec.max_violation >= 0


def test_callback_with_xk_signature_gets_x():
    seen = []
    result = _solve(hs35(), callback=lambda xk: seen.append(xk))
    assert len(seen) == result.nit
    np.testing.assert_array_equal(seen[-1], result.x)


@pytest.mark.parametrize('how', ['return_true', 'raise_stop_iteration'])
def test_callback_stops_the_run(how):
    def callback(intermediate_result):
        if intermediate_result.nit == 3:
            if how == 'return_true':
                return True
            raise StopIteration

    result = _solve(hs71(), callback=callback)
    assert result.nit == 3
    assert result.status == 99 and not result.success
    assert result.nfev == 4  # start + 3 iterations
    assert len(result.history) == 4


def test_resume_from_history_gives_same_answer_as_uninterrupted_run():
    problem = hs71()
    full = _solve(problem)
    partial = _solve(problem, callback=lambda intermediate_result: intermediate_result.nit == 3)
    assert partial.nit == 3 < full.nit
    resumed = _solve(problem, options={'history': partial.history})
    np.testing.assert_array_equal(resumed.x, full.x)
    assert resumed.fun == full.fun
    assert resumed.nit == full.nit
    # Counters are cumulative over the interrupted and the resumed parts.
    assert resumed.nfev == full.nfev
    assert resumed.ngev_by_source == full.ngev_by_source


def test_ask_tell_driver_matches_dynamic_q_and_can_stop():
    problem = hs35()

    def evaluate(x):
        return problem['fun'](x), np.array([x[0] + x[1] + 2.0 * x[2] - 3.0]), None

    def gradient(x):
        return problem['jac'](x), np.array([[1.0, 1.0, 2.0]]), None

    lower, upper = np.zeros(3), np.full(3, np.inf)
    reference = dynamic_q(evaluate, gradient, problem['x0'], lower, upper)
    driver = DynamicQ(problem['x0'], lower, upper)
    records = []
    while (request := driver.ask()) is not None:
        kind, x = request
        if kind == 'evaluate':
            record = driver.tell(evaluate(x))
        else:
            record = driver.tell(gradient(x), source='full')
        if record is not None:
            records.append(record)
    result = driver.result()
    np.testing.assert_array_equal(result.x, reference.x)
    assert result.ngev_by_source == {'full': reference.ngev}
    assert len(records) == result.nit + 1  # the start point is a record too
    _assert_at_optimum(result, problem)

    driver = DynamicQ(problem['x0'], lower, upper)
    driver.tell(evaluate(driver.ask()[1]))
    driver.stop('cancelled')
    assert driver.done and driver.ask() is None
    stopped = driver.result()
    assert stopped.status == 99 and stopped.message == 'cancelled'
    with pytest.raises(RuntimeError, match='no pending request'):
        driver.tell((0.0, None, None))


def test_maxiter_stops_unsuccessfully():
    result = _solve(rosenbrock_interior(), options={'maxiter': 5})
    assert result.nit == 5 and result.status == 3 and not result.success
    assert result.ngev == 5  # no gradient is asked at the last point


def test_results_are_deterministic():
    first = _solve(hs7())
    second = _solve(hs7())
    np.testing.assert_array_equal(first.x, second.x)
    assert first.nfev == second.nfev


def test_bad_input_raises_value_error():
    problem = hs35()
    with pytest.raises(ValueError, match='length of x0'):
        dynamic_q(lambda x: (0.0, None, None), lambda x: (x, None, None), [0.5, 0.5], [0, 0, 0])
    with pytest.raises(ValueError, match='finite'):
        minimize(problem['fun'], [np.nan, 0.5, 0.5])
    with pytest.raises(ValueError, match='inverted'):
        minimize(problem['fun'], [0.5, 0.5, 0.5], bounds=[(1.0, 0.0)] * 3)
    with pytest.raises(ValueError, match='outside the bounds'):
        minimize(problem['fun'], [-1.0, 0.5, 0.5], bounds=[(0.0, 1.0)] * 3)
    with pytest.raises(ValueError, match='pairs'):
        minimize(problem['fun'], [0.5, 0.5, 0.5], bounds=[(0.0, 1.0)] * 2)
    with pytest.raises(ValueError, match='unknown Dynamic-Q option'):
        minimize(problem['fun'], [0.5, 0.5, 0.5], options={'move_limit': 0.3})
    with pytest.raises(ValueError, match="'ineq' or 'eq'"):
        minimize(problem['fun'], [0.5, 0.5, 0.5], constraints={'type': 'le', 'fun': sum})
    with pytest.raises(ValueError, match='non-finite'):
        minimize(lambda x: float('nan'), [0.5, 0.5, 0.5])
    with pytest.raises(ValueError, match='rho_reduction'):
        DynamicQOptions(rho_reduction=1.5)


def test_config_analytic_section_equals_code_defaults():
    options = load_options(str(CONFIG), 'analytic')
    assert options == DynamicQOptions(lfopc=options.lfopc)
    assert LfopOptions.from_mapping(options.lfopc) == LfopOptions()
    vehicle = load_options(str(CONFIG), 'vehicle')
    assert vehicle.rho_min == 1e-3 and vehicle.curvature_cap == 1e3  # physics-reference 1.2-1.3
    with open(CONFIG, encoding='utf-8') as stream:
        data = yaml.safe_load(stream)
    assert data['finite_difference']['h'] == 0.025  # physics-reference 1.8
