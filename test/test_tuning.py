"""The optimisation loop counts model runs as the paper does (section 2)."""

import numpy as np
import pytest

from suspension_tuning.tuning import FullEvaluation, TuningRequest, centre, optimise

TARGET = np.array([0.3, 0.7])


def quadratic_model(points):
    # f = |x - target|^2, one constraint g = x1 + x2 - 0.8 <= 0 (active at the optimum).
    points = np.atleast_2d(points)
    f = np.sum((points - TARGET) ** 2, axis=1)
    g = (points[:, 0] + points[:, 1] - 0.8)[:, None]
    return FullEvaluation(f=f, g=g, inputs={'x': points[0].copy()})


def analytic_gradient(x, inputs):
    # The inputs passed through are those of the full-model run at the same x.
    np.testing.assert_array_equal(inputs['x'], x)
    return 2.0 * (x - TARGET), np.array([[1.0, 1.0]])


OPTIONS = {'xtol': 1e-7, 'ftol': 1e-12, 'maxiter': 60}
# Optimum of min |x-(0.3,0.7)|^2 s.t. x1+x2 <= 0.8: projection onto the line,
# x* = (0.3,0.7) - 0.1*(1,1) = (0.2, 0.6), f* = 0.02 (hand calculation).
X_STAR = np.array([0.2, 0.6])


@pytest.mark.parametrize('source', ['full', 'simplified'])
def test_loop_reaches_the_constrained_optimum_and_counts_runs(source):
    request = TuningRequest('ride', 2, gradient_source=source, options=OPTIONS)
    result = optimise(request, quadratic_model, analytic_gradient)
    np.testing.assert_allclose(result.x, X_STAR, rtol=1e-4)
    assert result.f == pytest.approx(0.02, rel=1e-4)
    n = 2
    ngev = result.ngev_by_source[source]
    if source == 'full':
        # One full run per evaluation plus 2n per central-difference gradient.
        assert result.n_full_runs == result.nfev + 2 * n * ngev
        assert result.n_simplified_runs == 0
    else:
        # Paper section 2: one full run per iteration, 2n simplified runs per gradient.
        assert result.n_full_runs == result.nfev
        assert result.n_simplified_runs == 2 * n * ngev


def test_callback_can_cancel_between_iterations():
    request = TuningRequest('ride', 2, gradient_source='full', options=OPTIONS)
    seen = []
    result = optimise(request, quadratic_model, callback=lambda rec, cnt: seen.append(rec) or
                      len(seen) >= 2)
    assert len(seen) == 2
    assert result.status == 99  # stopped by the caller


@pytest.mark.parametrize('calls_before', [0, 7])
def test_a_model_run_cancelled_mid_iteration_stops_with_the_best_design_so_far(calls_before):
    """A model raising RunCancelled (a cancelled service call) stops the loop as a
    cancelling callback does: before any evaluation (0 calls), or inside a later
    iteration (full gradients: 1 + 2n = 5 calls per iteration, so the 8th call falls
    in the second iteration's gradient)."""
    from suspension_tuning.tuning import RunCancelled

    calls = []

    def model(points):
        calls.append(points)
        if len(calls) > calls_before:
            raise RunCancelled('cancelled while waiting')
        return quadratic_model(points)

    request = TuningRequest('ride', 2, gradient_source='full', options=OPTIONS)
    result = optimise(request, model)
    assert result.status == 99 and result.message == 'cancelled'
    if calls_before:
        assert result.nit >= 1 and 'x_best' in result
    else:
        assert 'nit' not in result and 'x_best' not in result and result.constraint_values == []


def test_start_defaults_to_the_centre_of_the_design_space():
    # Eqs. 6 and 8: bounds 0.001..1, centre 0.5005.
    assert TuningRequest('handling', 4).start == pytest.approx(centre(4))
    assert centre(4)[0] == pytest.approx(0.5005)


@pytest.mark.parametrize('kwargs, message', [
    ({'scenario': 'offroad', 'n_vars': 2}, 'unknown scenario'),
    ({'scenario': 'ride', 'n_vars': 3}, 'n_vars'),
    ({'scenario': 'ride', 'n_vars': 2, 'gradient_source': 'adjoint'}, 'gradient source'),
    ({'scenario': 'ride', 'n_vars': 2, 'x0': [0.5, float('nan')]}, 'NaN|nan|finite'),
    ({'scenario': 'ride', 'n_vars': 2, 'x0': [0.5, 1.5]}, 'bound|outside|range'),
    ({'scenario': 'ride', 'n_vars': 2, 'x0': [0.5]}, 'length|expected|shape'),
])
def test_bad_requests_are_rejected_with_clear_messages(kwargs, message):
    with pytest.raises(ValueError, match=message):
        TuningRequest(**kwargs)


def test_physical_settings_use_litres_at_the_edge():
    from suspension_tuning.tuning import physical_settings

    # Eq. 5: x = (1, 1) -> dpsf 3, gvol 0.6 L on both axles; x = 0.001 -> 0.1 + 0.001*2.9.
    top = physical_settings([1.0, 1.0])
    assert top == pytest.approx({'dpsf_front': 3.0, 'gas_volume_front_l': 0.6,
                                 'dpsf_rear': 3.0, 'gas_volume_rear_l': 0.6})
    low = physical_settings([0.001, 0.001, 1.0, 0.5])
    assert low['dpsf_front'] == pytest.approx(0.1029)
    assert low['gas_volume_front_l'] == pytest.approx(0.1005)
    assert low['gas_volume_rear_l'] == pytest.approx(0.35)


# ---- extra constraints from other scenarios and metrics ---------------------------------
def other_scenario_model(points):
    # A second scenario: its objective f = x1 + x2 and a metric 'roll_first_peak_deg'
    # = 10 (x1 + x2); no eq. 11 constraint is active (g = -1).
    points = np.atleast_2d(points)
    s = points[:, 0] + points[:, 1]
    return FullEvaluation(f=s, g=-np.ones((len(points), 4)), inputs={'x': points[0].copy()},
                          metric_names=['roll_first_peak_deg'], metrics=(10.0 * s)[:, None])


def other_scenario_gradient(x, inputs):
    np.testing.assert_array_equal(inputs['x'], x)  # the other scenario's own full run at x
    return np.array([1.0, 1.0]), np.zeros((4, 2))


def unconstrained_model(points):
    points = np.atleast_2d(points)
    return FullEvaluation(f=np.sum((points - TARGET) ** 2, axis=1),
                          g=-np.ones((len(points), 4)), inputs={'x': points[0].copy()})


def unconstrained_gradient(x, inputs):
    return 2.0 * (x - TARGET), np.zeros((4, 2))


@pytest.mark.parametrize('spec, source', [
    # f_hand <= 0.8 has the scenario's simplified model; the metric has none.
    (('handling', 'f_hand', 0.8), 'simplified'),
    (('handling', 'roll_first_peak_deg', 8.0), 'full'),
])
def test_a_constraint_from_another_scenario_is_respected_at_the_optimum(spec, source):
    # min |x - (0.3, 0.7)|^2 s.t. x1 + x2 <= 0.8 (through the other scenario): the
    # projection x* = (0.2, 0.6) of the single-scenario test above (hand calculation).
    request = TuningRequest('ride', 2, gradient_source='simplified', options=OPTIONS,
                            constraints=[spec])
    result = optimise(request, unconstrained_model, unconstrained_gradient,
                      constraint_models={'handling': other_scenario_model},
                      constraint_gradients={'handling': other_scenario_gradient})
    np.testing.assert_allclose(result.x, X_STAR, rtol=1e-4)
    assert result.constraint_gradient_sources == [source]
    assert result.constraints == [{'scenario': 'handling', 'quantity': spec[1].replace(
        'f_hand', 'f'), 'upper_bound': spec[2]}]
    # The constraint is active: its value sits at its bound, g = value - bound = 0.
    assert result.constraint_values[0] == pytest.approx(spec[2], abs=1e-6)
    assert len(result.g) == 5  # 4 eq. 11 constraints, then the extra one
    n, ngev = 2, result.ngev_by_source['simplified']
    # Per evaluation one full run of each scenario; a metric without a simplified model
    # adds 2n full central-difference runs of its scenario per gradient.
    extra = 2 * n * ngev if source == 'full' else 0
    assert result.n_full_runs == 2 * result.nfev + extra
    simplified_calls = 2 if source == 'simplified' else 1
    assert result.n_simplified_runs == simplified_calls * 2 * n * ngev


def test_full_gradients_difference_every_scenario_of_the_constraints():
    request = TuningRequest('ride', 2, gradient_source='full', options=OPTIONS,
                            constraints=['handling:f_hand<=0.8'])
    result = optimise(request, unconstrained_model,
                      constraint_models={'handling': other_scenario_model})
    np.testing.assert_allclose(result.x, X_STAR, rtol=1e-4)  # as above
    assert result.constraint_gradient_sources == ['full']
    n, ngev = 2, result.ngev_by_source['full']
    assert result.n_full_runs == 2 * (result.nfev + 2 * n * ngev)  # both scenarios


@pytest.mark.parametrize('spec, message', [
    (('offroad', 'f', 0.8), 'unknown scenario'),
    (('handling', 'roll_peak', 4.0), 'unknown metric'),
    (('ride', 'roll_first_peak_deg', 4.0), 'unknown metric'),  # a handling metric
    (('handling', 'f_hand', float('nan')), 'finite'),
    (('handling', 'f_hand', 'high'), 'number'),
    ('handling:f_hand<0.8', 'expected'),
    ('handling:f_hand<=abc', 'not a number'),
    ({'scenario': 'handling', 'quantity': 'f'}, 'upper_bound'),
])
def test_bad_constraint_specifications_are_rejected_with_clear_messages(spec, message):
    with pytest.raises(ValueError, match=message):
        TuningRequest('ride', 2, constraints=[spec])


def test_constraint_text_names_the_objective_and_is_read_back():
    from suspension_tuning.tuning import ConstraintSpec

    spec = ConstraintSpec.parse('handling: f_hand <= 0.8')
    assert (spec.scenario, spec.quantity, spec.upper_bound) == ('handling', 'f', 0.8)
    assert spec.label == 'handling:f_hand<=0.8'
    assert ConstraintSpec.parse(spec.label) == spec
    assert ConstraintSpec.parse('mixed:valve_switches<=4').has_simplified_model is False
    assert ConstraintSpec.parse('ride:g_fl<=0').has_simplified_model is True


def test_a_constraint_scenario_without_a_model_is_an_error():
    request = TuningRequest('ride', 2, gradient_source='full', constraints=['mixed:f<=1'])
    with pytest.raises(ValueError, match='needs its full model'):
        optimise(request, unconstrained_model)


def test_tuning_request_names_the_integrator_and_rejects_unknown_ones():
    from suspension_tuning.tuning import TuningRequest

    assert TuningRequest('ride', 2).integrator == ''  # the simulation's default
    assert TuningRequest('ride', 2, integrator='variable_step').integrator == 'variable_step'
    with pytest.raises(ValueError, match='unknown integrator'):
        TuningRequest('ride', 2, integrator='rk45')


def test_an_answer_the_tighter_check_finds_infeasible_is_continued_with_shifted_constraints():
    # The check model's constraint lies 0.05 higher than the run model's (as a loose
    # integrator's bias would): x1 + x2 - 0.75 <= 0, optimum (0.175, 0.575) by the same
    # projection as X_STAR, f = 2 * 0.125^2 = 0.03125 (hand calculation).
    def check_model(points):
        run = quadratic_model(points)
        return FullEvaluation(f=run.f, g=run.g + 0.05)

    request = TuningRequest('ride', 2, gradient_source='simplified', options=OPTIONS)
    plain = optimise(request, quadratic_model, analytic_gradient)
    checked = optimise(request, quadratic_model, analytic_gradient, check_model=check_model,
                       check_gtol=1e-6)
    check = checked.check
    assert not check['first']['feasible_check'] and check['first']['feasible_run']
    assert check['first']['offset'] == pytest.approx([0.05])
    assert check['continued'] and check['continuations'] == 1
    assert check['shift'] == pytest.approx([0.05])
    assert check['feasible_check'] and check['feasible_run']
    np.testing.assert_allclose(checked.x_best, [0.175, 0.575], atol=1e-4)
    assert checked.f_best == pytest.approx(0.03125, rel=1e-3)
    # the answer's g as the run's model gives it (the shift is not the model's)
    assert checked.g_best[0] == pytest.approx(-0.05, abs=1e-4)
    # paid: the first run's, the check's two and the continuation's evaluations (nfev,
    # that pass's) but its start, the first answer, answered from the values run before
    assert checked.n_full_runs == plain.n_full_runs + 2 + checked.nfev - 1
    assert [r['iteration'] for r in checked.history] == list(range(len(checked.history)))


def test_an_answer_the_tighter_check_finds_infeasible_is_continued_on_the_check_model():
    # The same 0.05 bias as above; continued on the check model itself, the run reaches
    # that model's optimum (0.175, 0.575), f = 0.03125 (hand calculation), and reports
    # its values there: g = 0 (active), not the run model's -0.05.
    calls = []

    def check_model(points):
        calls.append(len(np.atleast_2d(points)))
        run = quadratic_model(points)
        return FullEvaluation(f=run.f, g=run.g + 0.05, inputs=run.inputs)

    request = TuningRequest('ride', 2, gradient_source='simplified', options=OPTIONS)
    plain = optimise(request, quadratic_model, analytic_gradient)
    checked = optimise(request, quadratic_model, analytic_gradient, check_model=check_model,
                       check_gtol=1e-6, check_continue_by='tighter_model')
    check = checked.check
    assert check['continue_by'] == 'tighter_model'
    assert not check['first']['feasible_check'] and check['first']['feasible_run']
    assert check['continued'] and check['continuations'] == 1
    assert check['first_iteration'] == len(plain.history)
    np.testing.assert_allclose(checked.x_best, [0.175, 0.575], atol=1e-4)
    assert checked.f_best == pytest.approx(0.03125, rel=1e-3)
    assert checked.g_best[0] == pytest.approx(0.0, abs=1e-4)
    assert check['feasible_check'] and check['f_check'] == checked.f_best
    # paid: the first run's, the check's one run, then every continuation evaluation on
    # the check model but its start (the check's run of the first answer); no re-check
    assert checked.n_full_runs == plain.n_full_runs + sum(calls)
    assert sum(calls) == checked.nfev
    assert [r['iteration'] for r in checked.history] == list(range(len(checked.history)))


def test_a_continuation_on_the_check_model_at_the_iteration_limit_restarts_once():
    # With the simplified values given, the secant correction is on, and a corrected run
    # that reaches the iteration limit starts once more from its answer (restarts: 1,
    # config/optimiser.yaml): the first run and its continuation on the check model each
    # do, 2 iterations a run, and end at the check model's optimum (0.175, 0.575), f =
    # 0.03125 (hand calculation, as above).
    def gradient_with_values(x, inputs):
        df, dg = analytic_gradient(x, inputs)
        run = quadratic_model(x[None, :])
        return df, dg, np.r_[run.f, run.g[0]]

    def check_model(points):
        run = quadratic_model(points)
        return FullEvaluation(f=run.f, g=run.g + 0.05, inputs=run.inputs)

    request = TuningRequest('ride', 2, gradient_source='simplified',
                            options=OPTIONS | {'maxiter': 2})
    result = optimise(request, quadratic_model, gradient_with_values,
                      check_model=check_model, check_gtol=1e-6,
                      check_continue_by='tighter_model')
    assert result.check['continued'] and result.restarts == 2
    assert 'restarted 2 time(s)' in result.message
    np.testing.assert_allclose(result.x_best, [0.175, 0.575], atol=1e-4)
    assert result.f_best == pytest.approx(0.03125, rel=1e-3)
    assert [r['iteration'] for r in result.history] == list(range(len(result.history)))


def rough_model(points):
    # quadratic_model with deterministic ripples standing in for a loose integrator's
    # noise: 0.002 in f and 0.03 in g (the noise levels the run is given below)
    run = quadratic_model(points)
    p = np.atleast_2d(points)
    return FullEvaluation(f=run.f + 0.002 * np.sin(3000 * p[:, 1]),
                          g=run.g + 0.03 * np.sin(2000 * p[:, :1]), inputs=run.inputs)


ROUGH_START = np.array([0.04, 0.02])
ROUGH_OPTIONS = OPTIONS | {'noise_f': 2e-3, 'noise_g': 0.03}


def test_a_run_that_converged_away_from_its_answer_goes_on_from_its_last_iterate():
    # On the rippled model the noise test ends the run from (0.04, 0.02) at an iterate
    # its model calls infeasible, f about 0.019, while its answer, an earlier feasible
    # iterate, has f about 0.024: more than 1 % above.  The last iterate is checked
    # (one more paid run) and the run goes on from it on the check model, reaching that
    # model's optimum (0.2, 0.6), f = 0.02 (hand calculation, X_STAR).
    request = TuningRequest('ride', 2, ROUGH_START, gradient_source='simplified',
                            options=ROUGH_OPTIONS)
    plain = optimise(request, rough_model, analytic_gradient)
    assert plain.stop_test == 'noise' and plain.max_violation > 1e-3
    assert plain.f_best > 1.01 * plain.f
    result = optimise(request, rough_model, analytic_gradient, check_model=quadratic_model,
                      check_gtol=1e-6, check_continue_by='tighter_model',
                      check_last_gap=0.01)
    check = result.check
    assert check['continued'] and check['continued_from'] == 'last_iterate'
    assert check['first']['feasible_check']  # the old answer was valid, only worse
    np.testing.assert_allclose(result.x_best, X_STAR, atol=1e-4)
    assert result.f_best == pytest.approx(0.02, rel=1e-3)
    assert check['feasible_check'] and check['f_check'] == result.f_best
    # paid: the first run's, the checks of the answer and of the last iterate, and the
    # continuation's evaluations but its start (the last iterate's check)
    assert result.n_full_runs == plain.n_full_runs + 2 + result.nfev - 1
    # without the test (gap 0) the earlier iterate stays the answer
    kept = optimise(request, rough_model, analytic_gradient, check_model=quadratic_model,
                    check_gtol=1e-6, check_continue_by='tighter_model')
    np.testing.assert_array_equal(kept.x_best, plain.x_best)
    assert not kept.check['continued']


def test_the_answer_stays_when_the_continuation_from_the_last_iterate_finds_nothing_better():
    # The check model is feasible only within 1e-3 of the run's answer: the
    # continuation from the last iterate finds nothing feasible, and the answer is the
    # one checked first, with the check model's values, f = |x - (0.3, 0.7)|^2
    # (hand calculation at that x).
    request = TuningRequest('ride', 2, ROUGH_START, gradient_source='simplified',
                            options=ROUGH_OPTIONS)
    answer = optimise(request, rough_model, analytic_gradient).x_best

    def island(points):
        run = quadratic_model(points)
        far = np.linalg.norm(np.atleast_2d(points) - answer, axis=1) > 1e-3
        return FullEvaluation(f=run.f, g=run.g + 0.5 * far[:, None], inputs=run.inputs)

    result = optimise(request, rough_model, analytic_gradient, check_model=island,
                      check_gtol=1e-6, check_continue_by='tighter_model',
                      check_last_gap=0.01)
    assert result.check['continued_from'] == 'last_iterate, answer kept'
    np.testing.assert_array_equal(result.x_best, answer)
    assert result.f_best == pytest.approx(np.sum((answer - TARGET) ** 2), rel=1e-12)
    assert result.best_feasible and result.check['feasible_check']
    assert result.check['x_checked'] == answer.tolist()


def test_a_run_the_noise_test_ended_goes_on_on_the_less_noisy_check_model():
    # The run's model holds the constraint 0.03 stricter (x1 + x2 <= 0.77) and is given
    # noise levels 1e-3 in f, 0.05 in g: from (0.1, 0.2) the noise test ends it near its
    # optimum (0.185, 0.585), which the noise-free check model (x1 + x2 <= 0.8) confirms.
    # With refine_noise_stop the run goes on on the check model to its optimum
    # (0.2, 0.6), f = 0.02 (hand calculation, X_STAR); without, the answer stays.
    def strict(points):
        run = quadratic_model(points)
        return FullEvaluation(f=run.f, g=run.g + 0.03, inputs=run.inputs)

    request = TuningRequest('ride', 2, np.array([0.1, 0.2]), gradient_source='simplified',
                            options=OPTIONS | {'noise_f': 1e-3, 'noise_g': 0.05})
    checking = {'check_model': quadratic_model, 'check_gtol': 1e-6,
                'check_continue_by': 'tighter_model', 'check_noise': (0.0, 0.0)}
    kept = optimise(request, strict, analytic_gradient, **checking)
    assert kept.stop_test == 'noise' and kept.check['feasible_check']
    assert not kept.check['continued']
    np.testing.assert_allclose(kept.x_best, [0.185, 0.585], atol=1e-4)
    refined = optimise(request, strict, analytic_gradient, check_refine_noise_stop=True,
                       **checking)
    assert refined.check['continued']
    assert refined.check['continued_from'] == 'answer, noise stop'
    np.testing.assert_allclose(refined.x_best, X_STAR, atol=1e-4)
    assert refined.f_best == pytest.approx(0.02, rel=1e-3)
    # paid: the first run's, the check's one run, the continuation's evaluations but its
    # start (the check's run of the answer)
    assert refined.n_full_runs == kept.n_full_runs + refined.nfev - 1


def test_an_unknown_continuation_of_the_check_is_refused():
    request = TuningRequest('ride', 2, gradient_source='simplified', options=OPTIONS)
    with pytest.raises(ValueError, match='check_continue_by must be one of'):
        optimise(request, quadratic_model, analytic_gradient, check_model=quadratic_model,
                 check_continue_by='tighter')


def test_an_answer_the_check_confirms_is_not_continued():
    request = TuningRequest('ride', 2, gradient_source='simplified', options=OPTIONS)
    plain = optimise(request, quadratic_model, analytic_gradient)
    checked = optimise(request, quadratic_model, analytic_gradient,
                       check_model=quadratic_model, check_gtol=1e-6)
    assert checked.check['feasible_check'] and not checked.check['continued']
    assert checked.n_full_runs == plain.n_full_runs + 1  # the check's one run
    np.testing.assert_array_equal(checked.x_best, plain.x_best)


@pytest.mark.parametrize('interrupted_after', [1, 2])
def test_a_run_resumed_from_its_history_pays_what_the_uninterrupted_run_pays(
        interrupted_after):
    """The 2-variable handling (full gradients, the answer checked) interrupted after 1 or
    2 iterations and resumed from its records: the same full runs as without the break
    (the check of a resumed answer needs no new run of a design of the history)."""
    from suspension_tuning import evaluation
    from suspension_tuning.answer_check import check_options
    from suspension_tuning.studies.common import vehicle_options
    from suspension_tuning.tuning import RunCounter, with_noise_levels

    def full_model(points):
        run = evaluation.evaluate('handling', points)
        return FullEvaluation(run.f, run.g)

    def request(maxiter):
        options = with_noise_levels(vehicle_options(), 'handling') | {'maxiter': maxiter}
        return TuningRequest('handling', 2, None, 'full', options)

    def counts(record, counter):  # as the coordinator records each iteration's count
        record['n_full_runs'] = counter.full_runs

    checking = check_options('handling', 2)
    short = optimise(request(interrupted_after), full_model, callback=counts, **checking)
    resumed = optimise(request(5), full_model, history=short.history,
                       counter=RunCounter(full_runs=short.history[-1]['n_full_runs']),
                       **checking)
    straight = optimise(request(5), full_model, **checking)
    np.testing.assert_array_equal(resumed.x_best, straight.x_best)
    assert resumed.n_full_runs == straight.n_full_runs
