"""The answer checked at a tighter solver tolerance, and the run continued on that model
(suspension_tuning.answer_check, tuning.optimise's check_model)."""

import numpy as np
import pytest

from suspension_tuning.answer_check import CheckSettings, check_design, check_options
from suspension_tuning.evaluation import in_process_model
from suspension_tuning.optim.simplified_gradient import SimplifiedGradient
from suspension_tuning.studies.common import FD_STEP, vehicle_options
from suspension_tuning.studies.method_benchmark import benchmark_starts
from suspension_tuning.tuning import TuningRequest, optimise, with_noise_levels

GTOL = 5e-3  # config/vehicle.yaml integration.check.gtol: 0.05 % of the run beyond eq. 11


def test_a_noisy_answer_infeasible_at_the_check_is_continued_on_the_check_model():
    # 4-variable ride on the variable-step model (DOPRI5 at Adams' 1e-3): its answers lie
    # on the noisy model's tyre-hop boundary, which sits ~0.015 in g below the converged
    # one (docs/noise_study.md), so the check at 1e-6 finds them infeasible; the run goes
    # on on the check model and reports that model's values.  Which start ends exactly
    # on the boundary depends on the noise, that is on the machine's last bits (its
    # libm): the first of three benchmark starts whose answer the check refuses.
    options = with_noise_levels(vehicle_options(), 'ride', 'variable_step')
    checking = check_options('ride', 4)
    assert checking['check_continue_by'] == 'tighter_model'  # config/vehicle.yaml
    starts = dict(benchmark_starts(4))
    for label in ('lhs2', 'centre', 'lhs0'):
        request = TuningRequest('ride', 4, starts[label], 'simplified', options, FD_STEP,
                                integrator='variable_step')
        result = optimise(request, in_process_model('ride', 'variable_step'),
                          SimplifiedGradient('ride', 4, None, FD_STEP), **checking)
        if result.check['first']['max_violation_check'] > GTOL:
            break
    check = result.check
    assert check['first']['feasible_run'] and check['first']['max_violation_check'] > GTOL
    assert check['continued'] and check['continue_by'] == 'tighter_model'
    assert check['continuations'] == 1 and check['first_iteration'] > 0
    # the answer's values are the check model's own run of it (bit for bit)
    f, g = check_design('ride', 4, result.x_best)
    assert result.f_best == f and np.array_equal(result.g_best, g)
    assert check['feasible_check'] and np.max(g) <= GTOL
    assert check['max_violation_check'] == pytest.approx(max(0.0, float(np.max(g))))
    # the continuation's records after the first answer carry the check model's metrics
    later = [r for r in result.history if r['iteration'] >= check['first_iteration']]
    assert later and all('metrics' in r for r in later)


def test_a_check_setting_of_an_unknown_continuation_is_refused_by_name():
    with pytest.raises(ValueError, match=r"integration.check.continue_by must be one of "
                                         r"shift, tighter_model, got 'again'"):
        CheckSettings(1e-6, 1e-6, continue_by='again')


@pytest.mark.parametrize('continued_from, words', [
    ('answer', 'from the answer, which the check found infeasible'),
    ('answer, noise stop', 'where the noise test ended the run'),
    ('last_iterate', 'converged away from its answer:'),
    ('last_iterate, answer kept', 'so the answer stays'),
])
def test_the_check_note_says_where_a_continuation_started(continued_from, words):
    from suspension_tuning.nodes.coordinator import check_note

    first = {'feasible_run': True, 'feasible_check': True, 'max_violation_check': 0.0015}
    note = check_note({'first': first, 'check_gtol': GTOL, 'continued': True,
                       'continue_by': 'tighter_model', 'continued_from': continued_from,
                       'max_violation_check': 0.0, 'feasible_check': True})
    assert words in note
    assert note.endswith("the answer's max g there 0 (feasible)")
