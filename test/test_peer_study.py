"""The peer comparison's figures, table and data profile, on hand-made results."""

from __future__ import annotations

import math

from suspension_tuning.studies import method_benchmark as mb
from suspension_tuning.studies import peer_study

BUDGET = 300  # the peers' budget of full runs


def result(method, to_solve, gap, viol=0.0, feasible=True, runs=300):
    return mb.StartResult(method, 's', [0.5] * 4, [0.5] * 4, 0.1, viol, 0.1, viol, gap,
                          feasible, to_solve <= BUDGET, to_solve, runs, 1.0,
                          budget_gap_pct=gap, budget_max_violation=viol,
                          budget_feasible=feasible)


def case():
    inf = math.inf
    results = {
        'dq_simplified': [result('dq_simplified', v, 0.2, runs=30) for v in (10, 12, 14)],
        'dq_full': [result('dq_full', v, 0.1) for v in (150, 320, 400)],  # not capped
        'cobyla': [result('cobyla', v, g) for v, g in ((60, 0.5), (80, 0.4), (inf, 2.0))],
        'optuna_tpe': [result('optuna_tpe', inf, 5.0, viol=0.01, feasible=False)] * 3,
        'slsqp': [result('slsqp', v, 0.0) for v in (350, 400, 500)],  # beyond the budget
    }
    ours = mb.median_full_runs(results['dq_simplified'])
    return {'scenario': 'ride', 'n_vars': 4, 'integrator': 'fixed_step', 'budget': BUDGET,
            'calibration_runs': 16, 'results': results, 'starts': [('s', [0.5] * 4)] * 3,
            'peers': mb.peer_figures(results, ours, 16, BUDGET)}


def test_the_best_peer_is_the_smallest_median_within_the_budget():
    p = case()['peers']
    assert p['peer_medians']['slsqp'] == math.inf  # 350 and more: beyond 300
    assert p['best_peer'] == 'cobyla' and p['peer_best_full_runs'] == 80
    assert p['full_runs_ratio_vs_best_peer'] == 80 / 12  # ours: median of 10, 12, 14
    assert p['full_runs_ratio_vs_best_peer_with_calibration'] == 80 / (12 + 16)


def test_figures_cap_peers_at_the_budget_but_not_dynamic_q():
    figs = peer_study.case_figures(case())
    assert figs['dq_full']['median_full_runs'] == 320  # Dynamic-Q is not capped
    assert figs['slsqp']['starts_solved'] == 0
    assert figs['cobyla']['starts_solved'] == 2 and figs['cobyla']['worst_gap_pct'] == 2.0
    tpe = figs['optuna_tpe']
    assert math.isnan(tpe['median_gap_pct']) and tpe['final_violation'] == 0.01


def test_the_table_and_the_data_profile(tmp_path):
    c = case()
    text = peer_study.markdown([c])
    assert '| COBYLA | 80 / +0.50 % |' in text
    assert '| SLSQP, default step | not reached / +0.00 % |' in text
    assert '| ours incl. calibration | 28 |' in text  # 12 + 16 calibration runs
    path = peer_study.data_profile([c], tmp_path / 'profile.png')
    assert path.stat().st_size > 10_000  # a rendered figure, not an empty file
