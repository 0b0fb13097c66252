"""Tests of Dynamic-Q (Snyman and Hay 2002) on analytic problems with published optima.

The problems and their optima, each with its source (Hock and Schittkowski 1981 for
HS21, HS35, HS71, HS6, HS7; hand calculations for the others), are in
suspension_tuning/optim/problems.py, shared with benchmarks/bench_optimiser.py.
Accuracy asked by the issue: 1e-4 relative (on x, with max(1, |x*|) as the scale, and
on f; absolute where f* = 0).
"""

from pathlib import Path

import numpy as np
import pytest
import yaml

from suspension_tuning.optim import (
    DynamicQ,
    DynamicQOptions,
    LfopOptions,
    central_difference,
    dynamic_q,
    load_options,
    minimize,
)
from suspension_tuning.optim.problems import (
    PROBLEMS,
    constrained_quadratic,
    hs7,
    hs35,
    hs71,
    rosenbrock_interior,
)

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'optimiser.yaml'
REL = 1e-4  # the accuracy requirement


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
    # the constraint) reach the same optimum.
    problem = hs35()
    constraints = [{'type': c['type'], 'fun': c['fun']} for c in problem['constraints']]
    result = _solve(problem, jac=None, constraints=constraints)
    assert result.success
    _assert_at_optimum(result, problem)
    assert result.ngev_by_source == {'central_difference': result.nit}
    assert result.nfev_fd == 6 * result.nit  # 2n objective calls per gradient, n = 3
    assert result.ncev_fd == 6 * result.nit  # and 2n calls of the constraint function


def test_nfev_counts_every_call_of_fun_including_finite_differences():
    # As scipy.optimize.minimize reports it (SLSQP: nfev = every call of fun, njev =
    # gradient evaluations, analytic or by differences): counted by wrappers here.
    problem = hs35()
    calls = {'fun': 0, 'con': 0}

    def fun(x):
        calls['fun'] += 1
        return problem['fun'](x)

    def con(x):
        calls['con'] += 1
        return problem['constraints'][0]['fun'](x)

    result = minimize(fun, problem['x0'], bounds=problem['bounds'],
                      constraints=[{'type': 'ineq', 'fun': con}])
    assert result.success
    _assert_at_optimum(result, problem)
    assert result.nfev == calls['fun']
    # one call per evaluated point plus 2n = 6 per central-difference gradient (n = 3)
    assert result.nfev == result.n_evaluations + 6 * result.njev
    assert result.nfev_fd == 6 * result.njev
    assert result.njev == result.nit  # one gradient per iteration
    assert result.constr_nfev == [calls['con']]
    assert result.constr_nfev == [result.n_evaluations + result.ncev_fd]
    assert result.constr_njev == [0]  # no jac given: differences only (trust-constr's count)


def test_nfev_with_jac_true_counts_one_call_per_point():
    # fun returns (f, grad): the gradient at an evaluated point reuses that call, as
    # SciPy's MemoizeJac does, so every call of fun is one point (nfev = evaluations).
    problem = hs71()
    calls = []

    def fun_and_grad(x):
        calls.append(np.copy(x))
        return problem['fun'](x), problem['jac'](x)

    result = minimize(fun_and_grad, problem['x0'], jac=True, bounds=problem['bounds'],
                      constraints=problem['constraints'])
    reference = _solve(problem)
    np.testing.assert_array_equal(result.x, reference.x)  # same run as with jac=callable
    assert result.nfev == len(calls) == result.n_evaluations == reference.nfev
    assert result.njev == result.nit
    assert len({c.tobytes() for c in calls}) == len(calls)  # never twice at one point


def test_x0_outside_the_bounds_is_clipped_into_them():
    # HS71's bounds are 1 <= x <= 5; (0, 6, 7, -2) clips to (1, 5, 5, 1), HS71's own
    # start (Hock and Schittkowski 1981), so the run is exactly the standard one.
    problem = hs71()
    standard = _solve(problem)
    calls = []

    def fun(x):
        calls.append(np.copy(x))
        return problem['fun'](x)

    clipped = minimize(fun, [0.0, 6.0, 7.0, -2.0], jac=problem['jac'],
                       bounds=problem['bounds'], constraints=problem['constraints'])
    np.testing.assert_array_equal(calls[0], [1.0, 5.0, 5.0, 1.0])
    np.testing.assert_array_equal(clipped.history[0]['x'], [1.0, 5.0, 5.0, 1.0])
    np.testing.assert_array_equal(clipped.x, standard.x)
    assert clipped.success
    _assert_at_optimum(clipped, problem)
    assert all(np.all((c >= 1.0) & (c <= 5.0)) for c in calls)
    # HS35 (x >= 0) from (-1, 2, -3), clipped to (0, 2, 0): still the optimum, with
    # finite differences too
    problem = hs35()
    problem['x0'] = [-1.0, 2.0, -3.0]
    result = _solve(problem, jac=None)
    np.testing.assert_array_equal(result.history[0]['x'], [0.0, 2.0, 0.0])
    assert result.success
    _assert_at_optimum(result, problem)


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
    assert len(calls) == result_guarded.nfev  # every call, differences included
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


@pytest.mark.parametrize('jac', ['analytic', 'central_difference'])
def test_resume_from_history_gives_same_answer_as_uninterrupted_run(jac):
    problem = hs71()
    if jac == 'central_difference':
        problem['jac'] = None
    full = _solve(problem)
    partial = _solve(problem, callback=lambda intermediate_result: intermediate_result.nit == 3)
    assert partial.nit == 3 < full.nit
    resumed = _solve(problem, options={'history': partial.history})
    np.testing.assert_array_equal(resumed.x, full.x)
    assert resumed.fun == full.fun
    assert resumed.nit == full.nit
    # Counters are cumulative over the interrupted and the resumed parts.
    for name in ('nfev', 'nfev_fd', 'n_evaluations', 'njev', 'constr_nfev', 'constr_njev'):
        assert resumed[name] == full[name], name
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


def test_iteration_limit_grows_in_proportion_above_maxiter_variables():
    # Rosenbrock (2 variables) does not converge in 6 iterations from (-1.2, 1), so each
    # run ends at its limit: maxiter 3 holds for up to maxiter_variables = 2 variables and
    # becomes ceil(3 x 2 / 1) = 6 when it holds for 1
    kept = _solve(rosenbrock_interior(), options={'maxiter': 3, 'maxiter_variables': 2})
    grown = _solve(rosenbrock_interior(), options={'maxiter': 3, 'maxiter_variables': 1})
    assert (kept.nit, kept.status) == (3, 3)
    assert (grown.nit, grown.status) == (6, 3)
    with pytest.raises(ValueError, match='maxiter_variables'):
        _solve(rosenbrock_interior(), options={'maxiter_variables': -1})


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
    with pytest.raises(ValueError, match='finite'):
        minimize(problem['fun'], [np.inf, 0.5, 0.5], bounds=[(0.0, 1.0)] * 3)
    with pytest.raises(ValueError, match='outside the bounds'):  # ask/tell: no clipping
        DynamicQ([-1.0, 0.5, 0.5], [0.0] * 3, [1.0] * 3)
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


@pytest.mark.parametrize('x0', [[0.9, 0.1], [0.001, 0.001], [1.0, 1.0]])
def test_vehicle_options_on_noisy_quadratic_with_large_step_differences(x0):
    # Normalised box [0.001, 1]^2 (paper eq. 6), f = (x1 - 0.3)^2 + (x2 - 0.7)^2 plus a
    # deterministic ripple of amplitude 1e-4 and wavelength 2 pi / 1000 standing in for the
    # full-model noise (paper Fig. 7).  Gradients: central differences with the default
    # h = 0.025 (physics-reference 1.8), which average the ripple: its contribution to a
    # difference quotient is at most 2e-4 / 0.05 = 4e-3, shifting the point where the
    # modelled gradient vanishes by at most 4e-3 / 2 = 2e-3 (Hessian 2 I).  Adding the
    # vehicle xtol 1e-3 gives the 3e-3 bound on the error below.
    lower, upper = np.full(2, 0.001), np.ones(2)

    def batch(points):
        points = np.atleast_2d(points)
        ripple = 1e-4 * np.sin(1000.0 * points[:, 0]) * np.cos(1000.0 * points[:, 1])
        return (points[:, 0] - 0.3) ** 2 + (points[:, 1] - 0.7) ** 2 + ripple

    def evaluate(x):
        assert np.all(x >= lower) and np.all(x <= upper)
        return float(batch(x)[0]), None, None

    def gradient(x):
        return central_difference(batch, x, 0.025, lower, upper), None, None

    options = load_options(str(CONFIG), 'vehicle')
    result = dynamic_q(evaluate, gradient, x0, lower, upper, options, gradient_source='simplified')
    assert result.success, result.message
    assert np.max(np.abs(result.x - [0.3, 0.7])) <= 3e-3
    assert result.nit <= options.maxiter
    assert result.ngev_by_source == {'simplified': result.ngev}


def _drive(options, gradient, source, x0=(0.9, 0.9)):
    """Run the driver on min |x - (0.3, 0.7)|^2 s.t. x1 + x2 <= 0.8 with a given gradient."""
    target = np.array([0.3, 0.7])
    driver = DynamicQ(np.array(x0), [0.0, 0.0], [1.0, 1.0], options)
    while (request := driver.ask()) is not None:
        kind, x = request
        if kind == 'evaluate':
            driver.tell((np.sum((x - target) ** 2), [x.sum() - 0.8], None))
        else:
            driver.tell(gradient(x, target), source=source)
    return driver.result()


def _slightly_wrong_gradient(x, target):
    # the constraint's slope 10 % too flat, as a simplified model's would be
    return 2.0 * (x - target), np.array([[0.9, 0.9]]), None


@pytest.mark.parametrize('source, zero', [('simplified', True), ('full', False)])
def test_surrogate_constraint_curvature_is_zero_only_for_simplified_gradients(source, zero):
    result = _drive({'surrogate_constraint_curvature': 'zero', 'maxiter': 8},
                    _slightly_wrong_gradient, source)
    b = [r['curvature']['b'][0] for r in result.history[2:]]  # from the 2nd iteration on
    assert all(v == 0.0 for v in b) == zero
    # objective curvature: interpolated as always (exact quadratic: a = 2, hand)
    a = [r['curvature']['a'] for r in result.history[2:]]
    np.testing.assert_allclose(a, 2.0, rtol=1e-9)


def test_surrogate_objective_curvature_nonnegative_clips_only_negative_values():
    def wrong_f_slope(x, target):  # a gradient of f 30 % too steep makes a < 0 possible
        return 1.3 * 2.0 * (x - target), np.array([[1.0, 1.0]]), None

    result = _drive({'surrogate_objective_curvature': 'nonnegative', 'maxiter': 10},
                    wrong_f_slope, 'simplified')
    a = [r['curvature']['a'] for r in result.history[2:]]
    assert min(a) >= 0.0
    with pytest.raises(ValueError, match='surrogate_objective_curvature'):
        DynamicQOptions(surrogate_objective_curvature='negative')


def test_a_single_short_step_does_not_stop_a_run_that_needs_two():
    # From a feasible start on the constraint, the first step is short (x0 is 1e-7 from
    # the optimum (0.2, 0.6), below xtol 1e-5): with converge_iterations 1 that step
    # ends the run; with 2 the run needs a second converged iteration.
    x0 = (0.2 + 1e-7, 0.6 - 1e-7)
    one = _drive({'converge_iterations': 1}, lambda x, t: (2.0 * (x - t), [[1.0, 1.0]], None),
                 'analytic', x0)
    two = _drive({'converge_iterations': 2}, lambda x, t: (2.0 * (x - t), [[1.0, 1.0]], None),
                 'analytic', x0)
    assert one.nit == 1 and one.status == 0
    assert two.nit == 2 and two.status == 0
    assert [r['converge_count'] for r in two.history] == [0, 1, 2]
    with pytest.raises(ValueError, match='converge_iterations'):
        DynamicQOptions(converge_iterations=0)


def test_curvatures_after_a_step_shorter_than_curvature_min_step_are_kept():
    def wrong_f_slope(x, target):  # 30 % too steep: each interpolation gives another a
        return 1.3 * 2.0 * (x - target), np.array([[1.0, 1.0]]), None

    fresh = _drive({'maxiter': 6}, wrong_f_slope, 'full')
    kept = _drive({'maxiter': 6, 'curvature_min_step': 10.0}, wrong_f_slope, 'full')
    a_fresh = [r['curvature']['a'] for r in fresh.history[2:]]
    a_kept = [r['curvature']['a'] for r in kept.history[2:]]
    assert len(set(np.round(a_fresh, 12))) > 1
    # every step is shorter than 10 (the box is [0, 1]^2): the first interpolated
    # curvature (iteration 2) is kept from then on
    assert a_kept == [a_kept[0]] * len(a_kept)
    with pytest.raises(ValueError, match='curvature_min_step'):
        DynamicQOptions(curvature_min_step=-1.0)


def _drive_rippled(noise_f):
    # min |x - (0.3, 0.7)|^2 s.t. x1 + x2 <= 0.8 (optimum (0.2, 0.6), f 0.02, by hand)
    # with a deterministic ripple of amplitude 2e-3 on f standing in for a model's
    # noise, and gradients 10 % too steep, as from another model (source 'simplified')
    target = np.array([0.3, 0.7])
    options = dict(load_options(str(CONFIG), 'vehicle').as_dict(), noise_f=noise_f)
    driver = DynamicQ(np.array([0.9, 0.9]), [0.001, 0.001], [1.0, 1.0], options)
    while (request := driver.ask()) is not None:
        kind, x = request
        if kind == 'evaluate':
            ripple = 2e-3 * np.sin(997.0 * x[0]) * np.cos(1013.0 * x[1])
            driver.tell((float(np.sum((x - target) ** 2) + ripple), [x.sum() - 0.8], None))
        else:
            driver.tell((1.1 * 2.0 * (x - target), np.array([[1.0, 1.0]]), None),
                        source='simplified')
    return driver.result()


def test_noise_test_ends_a_run_whose_steps_change_f_by_no_more_than_its_noise():
    without = _drive_rippled(0.0)
    with_noise = _drive_rippled(2e-3)  # the ripple's amplitude as the noise level
    assert without.stop_test == 'xtol' and without.status == 0
    assert with_noise.stop_test == 'noise' and with_noise.status == 5
    assert with_noise.success
    assert with_noise.nit < without.nit
    # the same reported design: the steps the noise test saves did not improve it
    np.testing.assert_allclose(with_noise.x_best, without.x_best)
    # near the optimum (0.2, 0.6): within the ripple's reach, 2e-3 of f ~ 0.02 of x
    assert np.max(np.abs(with_noise.x_best - [0.2, 0.6])) <= 0.02
    with pytest.raises(ValueError, match='noise_f'):
        DynamicQOptions(noise_f=-1.0)


def _corner_problem(kkt: bool, x0=(0.6, 0.7)):
    """min x1 + 2 x2 + (x1 - 0.2)^2 / 2 on [0, 1]^2, g = -1 (inactive): optimum (0, 0).

    At (0, 0) the gradient (0.8, 2) points out of the box through both lower bounds:
    the KKT conditions hold with the bounds' multipliers alone.
    """
    def evaluate(x):
        return float(x[0] + 2.0 * x[1] + 0.5 * (x[0] - 0.2) ** 2), np.array([-1.0]), np.zeros(0)

    def gradient(x):
        return np.array([1.0 + (x[0] - 0.2), 2.0]), np.zeros((1, 2)), np.zeros((0, 2))

    return dynamic_q(evaluate, gradient, list(x0), [0.0, 0.0], [1.0, 1.0],
                     {'bound_kkt': kkt, 'xtol': 1e-5, 'converge_iterations': 2})


def test_the_bound_kkt_test_stops_at_a_corner_where_the_gradient_points_out():
    without, with_kkt = _corner_problem(False), _corner_problem(True)
    assert without.stop_test == 'xtol'
    assert with_kkt.stop_test == 'bound_kkt' and with_kkt.status == 6 and with_kkt.success
    assert with_kkt.nfev < without.nfev  # the steps the xtol test waits for are saved
    np.testing.assert_allclose(with_kkt.x_best, [0.0, 0.0], atol=1e-5)  # xtol
    np.testing.assert_allclose(without.x_best, [0.0, 0.0], atol=1e-5)


def test_the_bound_kkt_test_waits_while_a_derivative_points_into_the_box():
    # (x1 - 0.2)^2 alone in x1: the optimum x1 = 0.2 is interior, so no corner is KKT
    def evaluate(x):
        return float(2.0 * x[1] + (x[0] - 0.2) ** 2), np.array([-1.0]), np.zeros(0)

    def gradient(x):
        return np.array([2.0 * (x[0] - 0.2), 2.0]), np.zeros((1, 2)), np.zeros((0, 2))

    result = dynamic_q(evaluate, gradient, [0.6, 0.7], [0.0, 0.0], [1.0, 1.0],
                       {'bound_kkt': True, 'xtol': 1e-5, 'converge_iterations': 2})
    assert result.stop_test == 'xtol'
    np.testing.assert_allclose(result.x_best, [0.2, 0.0], atol=1e-3)


def test_the_bound_kkt_test_waits_while_a_constraint_is_active():
    # the same corner, with g = x1 + x2 - 0 active there: a multiplier of g may be needed
    def evaluate(x):
        return (float(x[0] + 2.0 * x[1] + 0.5 * (x[0] - 0.2) ** 2),
                np.array([-(x[0] + x[1]) - 1e-9]), np.zeros(0))

    def gradient(x):
        return (np.array([1.0 + (x[0] - 0.2), 2.0]), np.array([[-1.0, -1.0]]),
                np.zeros((0, 2)))

    result = dynamic_q(evaluate, gradient, [0.6, 0.7], [0.0, 0.0], [1.0, 1.0],
                       {'bound_kkt': True, 'xtol': 1e-5, 'converge_iterations': 2})
    assert result.stop_test != 'bound_kkt'


def test_a_cycle_of_iterates_halves_the_move_limit_and_the_run_converges():
    # min (x - 0.5)^2 on [0.001, 1] with a model's slope: the right sign, size 1
    # everywhere (a function of x alone, as simplified gradients without the
    # correction), and no curvature: each step goes to the move limit.  From 0.001
    # with rho0 = 0.3 the iterates run 0.301, 0.901 (worse: rho 0.3), 0.601, 0.001
    # (worse), and the next step would repeat 0.301 with rho 0.6 for ever (hand).
    # Halving rho where an iterate returns turns the cycle into a bisection.
    def f(x):
        return float((x[0] - 0.5) ** 2), np.zeros(0), np.zeros(0)

    def slope(x):
        return np.array([1.0 if x[0] > 0.5 else -1.0]), np.zeros((0, 1)), np.zeros((0, 1))

    result = dynamic_q(f, slope, [0.001], [0.001], [1.0],
                       {'maxiter': 40, 'surrogate_objective_curvature': 'zero'})
    xs = [float(r['x'][0]) for r in result.history]
    np.testing.assert_allclose(xs[:6], [0.001, 0.301, 0.901, 0.601, 0.001, 0.301], atol=1e-8)
    assert xs[6] == pytest.approx(0.451, abs=1e-8)  # rho halved to 0.15 at the return
    assert result.status != 3  # not the iteration limit
    assert abs(result.x_best[0] - 0.5) < 1e-3
