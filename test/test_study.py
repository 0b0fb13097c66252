"""Method study: run counts add up, the reference is the best, bags reopen.

One quick case: handling, 2 variables, both start points, one calibration of 16 samples,
an 11 x 11 reference grid.  The handling optimum lies at the corner (dpsf = 3,
gas = 0.1 L: x = (1, 0.001), the stiffest car rolls least, eq. 10) which is a grid point,
so the grid alone must find it.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from suspension_tuning.bag.reader import read_messages
from suspension_tuning.inspect_bag import summary
from suspension_tuning.studies.common import (
    StudyRun,
    active_constraints,
    grid_designs,
    start_point,
)
from suspension_tuning.studies.method_study import (
    cost_ratios,
    markdown_tables,
    run_case,
    run_study,
)
from suspension_tuning.study import main
from suspension_tuning.vehicle.design import X_LOWER, X_UPPER

N = 2  # design variables of the quick case (eq. 5)
SAMPLES = 16  # eq. 25 calibration samples: 4 corners + 12 LHS points for n = 2
GRID = 11  # reference grid points per axis: spacing 0.0999, corners included


@pytest.fixture(scope='module')
def case(tmp_path_factory):
    bags = tmp_path_factory.mktemp('study') / 'bags'
    return run_case(
        'handling', N, ('centre', 'baseline'), (SAMPLES,), GRID, bags, log=lambda _: None
    )


def runs_of(case, method: str) -> list[StudyRun]:
    return [r for r in case['runs'] if r.method == method]


def test_every_method_runs_from_both_start_points(case):
    names = sorted(r.name for r in case['runs'])
    assert names == sorted(
        [
            'handling_2var_centre_dq_simplified_cal16',
            'handling_2var_baseline_dq_simplified_cal16',
            'handling_2var_centre_dq_full',
            'handling_2var_baseline_dq_full',
            'handling_2var_centre_slsqp',
            'handling_2var_baseline_slsqp',
            'handling_2var_reference',
        ]
    )


def distinct_designs(run):
    """The distinct designs among a Dynamic-Q run's iterates (the start included)."""
    return len({tuple(h['x']) for h in run.history})


def gradients(run):
    """Gradients a Dynamic-Q run asked for: one per iteration, and one more at the
    iterate where the bound-KKT test ended it (dynamic_q status 6), which takes no step."""
    return run.iterations + (run.details.get('stop_test') == 'bound_kkt')


def test_simplified_gradient_runs_cost_one_full_run_per_iteration(case):
    for r in runs_of(case, 'dq_simplified'):
        # Section 2: one full run per iterate (the start plus one per iteration) and 2n
        # simplified runs per gradient, plus one at the iterate itself for the
        # first-order correction's values.  An iterate that repeats an earlier design
        # (a step pinned at the bounds) is not run again.
        assert r.n_full_runs == distinct_designs(r) <= r.iterations + 1
        assert r.n_simplified_runs == (2 * N + 1) * gradients(r)
        assert r.n_calibration_runs == SAMPLES
        assert r.full_runs_with_calibration == r.n_full_runs + SAMPLES
        assert r.history[-1]['n_full_runs'] == r.n_full_runs


def test_full_gradient_runs_cost_two_n_plus_one_full_runs_per_iteration(case):
    for r in runs_of(case, 'dq_full'):
        # Section 2: "2n + 1 full simulations per iteration" (+ 1 for the start point;
        # a repeated design is not run again).
        assert r.n_full_runs == distinct_designs(r) + 2 * N * gradients(r)
        assert r.n_simplified_runs == 0 and r.n_calibration_runs == 0


def test_slsqp_pays_at_least_n_plus_one_full_runs_per_iteration(case):
    for r in runs_of(case, 'slsqp'):
        # 2-point forward differences: n runs per gradient plus >= 1 run per iteration.
        assert r.n_full_runs >= (N + 1) * r.iterations
        counts = [h['n_full_runs'] for h in r.history]
        assert counts == sorted(counts) and counts[-1] <= r.n_full_runs


def test_reference_is_no_worse_than_any_run(case):
    ref = case['reference']
    assert ref.n_full_runs >= GRID**N  # the grid's runs are counted
    for r in case['runs']:
        # The reference polishes from every method's final point: never worse (1e-12
        # relative: identical designs give identical bits, the model is deterministic).
        assert ref.f <= r.f + 1e-12 * abs(r.f)
        assert r.max_violation == 0.0  # eq. 11: no tyre lifts off in the lane change
    best_run = min(r.f for r in case['runs'] if r.method != 'reference')
    # The optimum is the grid corner x = (1, 0.001): the grid alone finds it exactly.
    assert ref.details['grid_best_x'] == [X_UPPER, X_LOWER]
    assert ref.details['grid_best_f'] == pytest.approx(best_run, rel=1e-6)
    np.testing.assert_allclose(ref.x, [X_UPPER, X_LOWER], atol=1e-6)


def test_distances_and_gaps_are_measured_against_the_reference(case):
    ref = case['reference']
    for r in case['runs']:
        assert r.distance_to_reference == pytest.approx(
            np.linalg.norm(np.subtract(r.x, ref.x)), abs=1e-12
        )
        assert r.gap_to_reference_pct == pytest.approx(100 * (r.f - ref.f) / abs(ref.f))
        # Every method reaches the corner optimum within the xtol of 1e-3 (optimiser.yaml).
        assert r.distance_to_reference < 1e-3


def test_cost_ratios_are_totals_over_the_start_points(case):
    ratios = cost_ratios(case, SAMPLES)
    simp = runs_of(case, 'dq_simplified')
    slsqp = sum(r.n_full_runs for r in runs_of(case, 'slsqp'))
    assert ratios['full_runs_ratio_vs_slsqp'] == pytest.approx(
        slsqp / sum(r.n_full_runs for r in simp)
    )
    assert ratios['full_runs_ratio_vs_slsqp_with_calibration'] == pytest.approx(
        slsqp / sum(r.n_full_runs + SAMPLES for r in simp)
    )
    table = markdown_tables([case], (SAMPLES,))
    for r in case['runs']:
        assert f'| {r.f:.5f} |' in table


def test_bags_reopen_and_report_the_same_optimum(case):
    for r in case['runs']:
        contents = read_messages(r.bag)
        assert contents.complete
        assert contents.counts()['/optimisation/progress'] == len(r.history)
        info = summary(r.bag)
        opt = info['optimum']
        assert opt['f'] == r.f and opt['x'] == r.x
        # the lane change lifts no tyre (g = -1): every reported design is feasible
        assert opt['feasible'] and opt['source'] == 'result'
        assert info['iterations'][opt['best_iteration']]['x'] == r.x
        assert opt['iterations'] == r.iterations
        assert info['evaluations']['n_full_runs'] == r.n_full_runs
        assert info['evaluations']['n_calibration_runs'] == r.n_calibration_runs
        assert info['run_config']['method'] == r.method
        assert [it['f'] for it in info['iterations']] == [h['f'] for h in r.history]


def test_dynamic_q_runs_report_the_best_feasible_iterate_and_keep_the_last_in_details(
        monkeypatch, tmp_path):
    """One Dynamic-Q step (maxiter 1) from the centre crosses a constraint the gradient
    misses: f = -(x1 + x2), g = x1 - 0.6, dg = 0 (a boundary the simplified model
    places only roughly).  The run reports the feasible start, not the last iterate."""
    from suspension_tuning.studies import common as study
    from suspension_tuning.tuning import FullEvaluation

    def fake_model(scenario, n_vars, integrator=None):
        def evaluate(points):
            return FullEvaluation(-points[:, 0] - points[:, 1],
                                  (points[:, 0] - 0.6)[:, None])
        return evaluate

    monkeypatch.setattr(study, 'full_model', fake_model)
    run, recorder = study.run_dynamic_q(
        'ride', 2, 'centre', 'simplified',
        lambda x, inputs: (np.array([-1.0, -1.0]), np.zeros((1, 2))),
        options={**study.vehicle_options(), 'maxiter': 1})
    centre = 0.5005  # (0.001 + 1) / 2, eqs. 6 and 8
    assert run.x == [centre, centre] and run.f == -2 * centre
    assert run.max_violation == 0.0  # g = 0.5005 - 0.6 < 0
    assert run.details['best_iteration'] == 0 and run.details['best_feasible']
    # the step of rho0 = 0.3 (optimiser.yaml, vehicle) along (1, 1) / sqrt(2): x1 = 0.7126
    assert run.details['x_last'][0] == pytest.approx(centre + 0.3 / np.sqrt(2))
    assert run.details['max_violation_last'] == pytest.approx(centre + 0.3 / np.sqrt(2) - 0.6)
    assert run.details['f_last'] < run.f and not run.success
    opt = summary(study.write_bag(tmp_path / 'bag', run, recorder))['optimum']
    assert (opt['x'], opt['best_iteration'], opt['feasible']) == (run.x, 0, True)
    assert opt['message'].startswith('best feasible design: iteration 0; Dynamic-Q stopped')


def test_grid_spans_the_bounds():
    grid = grid_designs(2, 3)
    assert grid.shape == (9, 2)  # 3^2 designs
    assert grid.min() == X_LOWER and grid.max() == X_UPPER


def test_start_points_are_centre_and_baseline():
    np.testing.assert_allclose(start_point('centre', 4), 0.5005)  # (0.001 + 1) / 2
    # Baseline 0.3 L, dpsf 1 (config/scenarios.yaml): (1 - 0.1) / 2.9 and (0.3 - 0.1) / 0.5.
    np.testing.assert_allclose(start_point('baseline', 2), [0.9 / 2.9, 0.4])


@pytest.mark.parametrize(
    'kwargs, message',
    [
        ({'scenarios': ('mixed',)}, 'unknown scenario'),
        ({'n_vars_list': (3,)}, 'n_vars must be 2 or 4'),
        ({'starts': ('corner',)}, 'unknown start point'),
        ({'calibration_samples': (1,)}, 'calibration sample counts'),
    ],
)
def test_bad_study_arguments_raise_value_error(tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        run_study(tmp_path, **kwargs)


def test_cli_rejects_an_unknown_scenario(capsys):
    with pytest.raises(SystemExit):
        main(['--scenarios', 'mixed'])
    assert 'invalid choice' in capsys.readouterr().err


def test_forward_difference_step_balances_truncation_and_noise():
    from suspension_tuning.studies.method_study import forward_difference_step

    # More & Wild: h* = 8^(1/4) sqrt(eps / |f''|); eps = 1e-4, f'' = 2 (f = x^2):
    # 1.6818 * sqrt(5e-5) = 0.011892
    assert forward_difference_step(1e-4, 2.0) == pytest.approx(0.011892, rel=1e-4)
    assert forward_difference_step(1e-4, -2.0) == forward_difference_step(1e-4, 2.0)
    # the error bound |f''| h / 2 + 2 eps / h is smaller at h* than at h*/2 and at 2 h*
    h = forward_difference_step(1e-4, 2.0)
    bound = [2.0 * k * h / 2 + 2e-4 / (k * h) for k in (0.5, 1.0, 2.0)]
    assert bound[1] < bound[0] and bound[1] < bound[2]
    assert forward_difference_step(0.0, 2.0) == 0.0  # no noise: any small step
    assert forward_difference_step(1e-4, 0.0) == 0.1  # no curvature: the largest step


def test_noisy_ratios_pick_the_cheapest_slsqp_variant_within_one_percent():
    from suspension_tuning.studies.method_study import StudyRun, noisy_ratios

    def run(method, start, runs, gap, cal=0):
        r = StudyRun('ride', 4, start, method, cal, [0.5] * 4, -0.15, [-1.0] * 4, 0.0, 5,
                     runs, 0, cal, 1.0)
        r.gap_to_reference_pct, r.gap_to_fixed_reference_pct = gap, gap + 0.1
        return r

    case = {'runs': [run('dq_simplified', 'centre', 7, 0.2, 16),
                     run('dq_simplified', 'baseline', 9, 0.3, 16),
                     run('slsqp', 'centre', 40, 6.0), run('slsqp', 'baseline', 50, 5.0),
                     run('slsqp_best_fd', 'centre', 60, 0.5),
                     run('slsqp_best_fd', 'baseline', 70, 0.9)]}
    c = noisy_ratios(case, 16)
    # default SLSQP is cheaper but 6 % off: the noise-optimal variant is the one within 1 %
    assert c['best_slsqp_variant'] == 'slsqp_best_fd' and c['slsqp_within_gap']
    assert c['full_runs_ratio_vs_slsqp_noisy'] == pytest.approx(130 / 16)
    assert c['full_runs_ratio_vs_slsqp_noisy_with_calibration'] == pytest.approx(130 / 48)
    assert c['optimum_gap_pct_noisy'] == pytest.approx(0.3)
    assert c['slsqp_default_gap_pct_noisy'] == pytest.approx(6.0)


def test_study_run_configuration_names_the_integrator():
    from suspension_tuning.studies.common import StudyRun, run_config

    run = StudyRun('ride', 2, 'centre', 'slsqp', 0, [0.5, 0.5], -0.15, [-1.0] * 4, 0.0, 3,
                   20, 0, 0, 1.0, details={'integrator': 'variable_step', 'eps': 0.07})
    config = run_config(run)
    assert config['integrator'] == 'variable_step'  # what the bag's run_config records
    assert config['method'] == 'slsqp' and config['eps'] == 0.07


def test_active_constraints_are_those_within_the_tolerance_of_zero():
    # ACTIVE_G_TOL = 0.05: g = -0.05 (9.5 % of the time off the ground) counts, -0.06 not
    assert active_constraints([-0.06, -0.05, 0.0, 0.3]) == ['FR', 'RL', 'RR']
    assert active_constraints([-1.0, -1.0, -1.0, -1.0]) == []


def test_table_reports_active_tyre_hop_constraints_and_violation(case):
    lane_change = markdown_tables([case], (SAMPLES,))
    # the lane change lifts no tyre: every final point has g = -1, no active constraint
    assert lane_change.count('| none | 0 |') == len(case['runs'])
    run = dataclasses.replace(case['runs'][0], g=[-0.5, -0.04, 0.02, -1.0], max_violation=0.02)
    table = markdown_tables([{**case, 'runs': [run, *case['runs'][1:]]}], (SAMPLES,))
    assert '| -0.500 | -0.040 | +0.020 | -1.000 | FR, RL | 0.02 |' in table
