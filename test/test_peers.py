"""The peer optimisers' adapters on an analytic constrained problem with a known optimum.

HS35 (Hock and Schittkowski 1981, ``optim.problems.hs35``): a convex quadratic in 3
variables with one linear inequality, active at x* = (4/3, 7/9, 4/9), f* = 1/9, from
(0.5, 0.5, 0.5).  The box [0, 3]^3 adds upper bounds (NOMAD and Optuna need a box)
that do not move the optimum: x >= 0 and x1 + x2 + 2 x3 <= 3 keep every xi <= 3.
"""

from __future__ import annotations

import numpy as np
import pytest

from suspension_tuning.optim.problems import hs35
from suspension_tuning.studies import peers

PROBLEM = hs35()
LOWER, UPPER = [0.0] * 3, [3.0] * 3
BUDGET = 100  # runs per peer: a third of the study's budget keeps the test short
F0 = 2.25  # f at the start (0.5, 0.5, 0.5)


def f_and_g(x):
    return PROBLEM['fun'](x), np.array([-PROBLEM['constraints'][0]['fun'](x)])


@pytest.fixture(scope='module', params=peers.PEERS)
def peer_run(request):
    return request.param, peers.minimise(request.param, f_and_g, PROBLEM['x0'], LOWER, UPPER,
                                         BUDGET)


def test_a_peer_starts_at_x0_and_counts_every_distinct_design_once(peer_run):
    method, run = peer_run
    evals = run.evaluations
    assert evals[0]['x'] == PROBLEM['x0']  # the start is the first run (Optuna: enqueued)
    assert 1 <= len(evals) <= BUDGET
    assert [e['n_full_runs'] for e in evals] == list(range(1, len(evals) + 1))
    assert len({tuple(e['x']) for e in evals}) == len(evals)  # a repeat costs nothing


# Tolerances on f - f*: the model-based trust-region methods converge on this smooth
# problem within ~45 runs (to 1e-4, 5e-5 of f0 - f* = 2.14); MADS refines its mesh more
# slowly (9e-5 after 100 runs: 1e-3 leaves a margin); TPE samples and does not converge,
# it only has to be far better than the start (0.2, a tenth of f0 - f*; 0.04 measured).
TOLERANCE = {'cobyla': 1e-4, 'cobyqa': 1e-4, 'nomad': 1e-3, 'optuna_tpe': 0.2}


def test_a_peer_finds_the_known_constrained_optimum(peer_run):
    method, run = peer_run
    best = run.best_feasible(gtol=1e-6)  # feasible to rounding: the constraint is linear
    assert best is not None
    assert best['f'] - PROBLEM['f_star'] <= TOLERANCE[method]
    assert best['f'] >= PROBLEM['f_star'] - 1e-6  # nothing feasible lies below f*


def test_a_peer_stops_at_the_budget_and_at_a_stop_condition():
    def near(rec):  # within 0.5 of f*, feasible: reached within a few dozen runs
        return rec['max_violation'] == 0 and rec['f'] - PROBLEM['f_star'] <= 0.5

    small = peers.minimise('nomad', f_and_g, PROBLEM['x0'], LOWER, UPPER, budget=10)
    assert len(small.evaluations) == 10  # NOMAD's MAX_BB_EVAL and the problem's budget
    problem = peers.CountedProblem(f_and_g, LOWER, UPPER, BUDGET, stop_when=near)
    stopped = peers.run_adapter('cobyla', problem, PROBLEM['x0'])
    assert near(stopped.evaluations[-1])
    assert not any(near(e) for e in stopped.evaluations[:-1])
    assert stopped.message.startswith('stopped after')


def test_an_unknown_peer_is_refused():
    with pytest.raises(ValueError, match='unknown peer'):
        peers.minimise('gp', f_and_g, PROBLEM['x0'], LOWER, UPPER)


@pytest.mark.parametrize('method', peers.PEERS)
def test_a_peer_goes_on_past_runs_that_fail(method):
    # a corner of the box where the model fails (f = g = inf, as FullModelCache gives a
    # run whose state turns non-finite): every peer treats it as a bad point and still
    # improves on the start; the failed runs count
    def failing(x):
        if x[0] < 0.3:
            return np.inf, np.array([np.inf])
        return f_and_g(x)

    run = peers.minimise(method, failing, PROBLEM['x0'], LOWER, UPPER, 60)
    assert run.best_feasible(gtol=1e-6)['f'] < F0
    assert 1 <= len(run.evaluations) <= 60


def test_the_study_model_counts_a_failed_run_as_infeasible(monkeypatch):
    from suspension_tuning.studies import common

    def run_full(scenario, designs, n_vars=None, integrator=None):
        raise ValueError('vehicle state must be finite, got (nan, ...)')

    monkeypatch.setattr(common, 'run_full', run_full)
    model = common.FullModelCache('mixed', 4)
    f, g = model(np.full(4, 0.001))
    assert f == np.inf and g.shape == (4,) and np.all(g == np.inf)
    assert model.n_runs == 1 and model.failed[0]['x'] == [0.001] * 4
