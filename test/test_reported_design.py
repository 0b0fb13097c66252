"""A run reports its best feasible iterate, and says plainly when no iterate was feasible.

The cases are built so that the last iterate is not the one to report: a linear
objective f = -(x1 + x2) falls towards the upper bounds, and a simplified gradient that
misses the constraint's slope (dg = 0, as a simplified model that places a boundary
only roughly) lets Dynamic-Q's one step (maxiter 1) cross the constraint.
"""

import numpy as np
import pytest

from suspension_tuning.reported_design import (
    best_record,
    reported_design,
    result_message,
    statement,
    stop_message,
)

START = 0.5005  # centre of the normalised design space, eqs. 6 and 8: (0.001 + 1) / 2
MAXITER_STOP = 'stopped: maximum number of iterations reached'  # dynamic_q.STATUS_MESSAGES[3]


def _fake_run(constraint_offset: float):
    """tuning.optimise on f = -(x1 + x2), g = x1 - constraint_offset, one iteration.

    Returns the optimiser's result and the IterationRecord messages the coordinator
    would have published (its ``on_iteration``).
    """
    from suspension_tuning.nodes.coordinator import record_to_msg
    from suspension_tuning.tuning import FullEvaluation, TuningRequest, optimise

    def full_model(points):
        points = np.atleast_2d(points)
        return FullEvaluation(-points[:, 0] - points[:, 1],
                              (points[:, 0] - constraint_offset)[:, None])

    def blind_gradient(x, inputs):
        # the true df; dg = 0: the constraint looks flat, so the step ignores it
        return np.array([-1.0, -1.0]), np.zeros((1, 2))

    history = []
    result = optimise(TuningRequest('ride', 2, None, 'simplified', {'maxiter': 1}),
                      full_model, blind_gradient,
                      lambda record, counts: history.append(record_to_msg(record, counts, 0.0)))
    return result, history


def test_the_action_result_reports_the_feasible_start_when_the_last_iterate_is_infeasible():
    from suspension_tuning.nodes.coordinator import action_result
    from suspension_tuning.tuning import RunCounter, physical_settings

    # g = x1 - 0.6: the start (x1 = 0.5005) is feasible, g = -0.0995; the step of
    # length rho0 = 0.3 along (1, 1) / sqrt(2) reaches x1 = 0.7126, g = +0.1126.
    result, history = _fake_run(0.6)
    assert result.g[0] == pytest.approx(START + 0.3 / np.sqrt(2) - 0.6)  # the last iterate
    assert result.f < -2 * START  # lower than the start's f, but infeasible

    msg = action_result(result, history, 0.0, RunCounter())
    assert list(msg.x) == [START, START]
    assert msg.f == -2 * START
    assert list(msg.g) == [pytest.approx(START - 0.6)]
    assert msg.feasible and msg.best_iteration == 0 and msg.max_violation == 0.0
    assert list(msg.physical_values) == list(physical_settings([START, START]).values())
    assert msg.message == ('best feasible design: iteration 0; Dynamic-Q '
                           f'{MAXITER_STOP} (last iterate infeasible)')
    assert not msg.success  # Dynamic-Q stopped on its iteration limit, not converged
    # nothing is lost: the last iterate is the history's last record (iterations 0, 1)
    assert [r.iteration for r in msg.history] == [0, 1]
    np.testing.assert_array_equal(msg.history[-1].x, result.x)


def test_no_feasible_design_is_said_plainly_and_the_least_violating_one_is_reported():
    from suspension_tuning.nodes.coordinator import action_result
    from suspension_tuning.tuning import RunCounter

    # g = x1 + 0.25 > 0 on the whole box (x1 >= 0.001): nothing is feasible.  The
    # start violates least, g = 0.7505; the step raises x1 and g.
    result, history = _fake_run(-0.25)
    assert result.g[0] > START + 0.25

    msg = action_result(result, history, 0.0, RunCounter())
    assert not msg.feasible and not msg.success
    assert msg.best_iteration == 0 and list(msg.x) == [START, START]
    assert msg.max_violation == pytest.approx(START + 0.25)
    assert msg.message == ('no feasible design found: the reported design is the least '
                           'violating one (max g = 0.7505), iteration 0; Dynamic-Q '
                           f'{MAXITER_STOP} (last iterate infeasible)')


def test_reported_design_reads_the_best_point_fields_and_none_without_them():
    result, _ = _fake_run(0.6)
    design = reported_design(result)
    assert design.x == [START, START] and design.iteration == 0 and design.feasible
    assert design.statement == 'best feasible design: iteration 0'
    assert reported_design({'x': [START, START]}) is None  # no point was evaluated


def test_the_stop_message_is_recovered_from_a_result_message():
    design = reported_design(_fake_run(0.6)[0])
    message = result_message(design, MAXITER_STOP)
    assert stop_message(message) == MAXITER_STOP
    assert stop_message('converged: step shorter than xtol') == 'converged: step shorter than xtol'
    assert result_message(None, 'cancelled') == 'cancelled'  # nothing evaluated
    # the violation with 4 significant digits (format .4g)
    assert statement(False, 4, 0.0444) == ('no feasible design found: the reported design '
                                           'is the least violating one (max g = 0.0444), '
                                           'iteration 4')


def test_best_record_follows_dynamic_q_rule_on_recorded_iterates():
    gtol = 1e-3  # config/optimiser.yaml, vehicle section
    records = [
        {'f': 0.20, 'max_violation': 0.0},     # feasible
        {'f': 0.10, 'max_violation': 0.05},    # lowest f, infeasible
        {'f': 0.15, 'max_violation': 0.001},   # violation == gtol: feasible, best
        {'f': 0.15, 'max_violation': 0.0},     # equal f, later: not strictly better
        {'f': 0.12, 'max_violation': 0.002},   # last, infeasible
    ]
    assert best_record(records, gtol) == (2, True)
    infeasible = [{'f': 1.0, 'max_violation': 0.3}, {'f': 2.0, 'max_violation': 0.2},
                  {'f': 0.5, 'max_violation': 0.2}]
    assert best_record(infeasible, gtol) == (1, False)  # least violation, the first of two
    assert best_record([], gtol) is None


@pytest.mark.parametrize('status, test', [(0, 'xtol'), (1, 'ftol'), (2, 'rho_min'),
                                          (5, 'noise'), (6, 'bound_kkt')])
def test_a_run_stopped_by_any_convergence_test_at_a_feasible_design_succeeds(status, test):
    from suspension_tuning.optim.dynamic_q import STOP_TESTS
    from suspension_tuning.reported_design import ReportedDesign, design_success

    assert STOP_TESTS[status] == test  # dynamic_q's status codes
    feasible = ReportedDesign(x=[0.5], f=0.1, g=[-0.1], iteration=2, feasible=True,
                              max_violation=0.0)
    assert design_success({'status': status}, feasible)
    assert not design_success({'status': status}, ReportedDesign(
        x=[0.5], f=0.1, g=[0.1], iteration=2, feasible=False, max_violation=0.1))
    assert not design_success({'status': 3}, feasible)  # the iteration limit: not converged
