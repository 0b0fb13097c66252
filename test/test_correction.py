"""The first-order (secant) correction of simplified gradients, and the smooth tyre-hop
measure it is used with."""

from pathlib import Path

import numpy as np
import pytest

from suspension_tuning.optim.correction import (
    CorrectionOptions,
    SecantCorrection,
    load_correction_options,
    poorly_seen,
)
from suspension_tuning.tuning import FullEvaluation, TuningRequest, optimise, verify_bounds
from suspension_tuning.vehicle.metrics import soft_tyre_hop_constraints, tyre_hop_constraints
from suspension_tuning.vehicle.simplified import run_simplified

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'optimiser.yaml'


def test_secant_updates_recover_a_linear_discrepancy_along_orthogonal_steps():
    # D(x) = A x + d0: Broyden's update makes C s = y along each step and leaves the
    # directions orthogonal to it alone, so steps along the two axes give C = A exactly
    # (hand: Broyden 1965, the rank-one update's secant and no-change conditions).
    a = np.array([[1.0, -2.0], [0.5, 3.0], [0.0, 0.0]])
    simp = np.array([0.0, 0.0, np.nan])  # the third row has no simplified model

    def full(x):
        return a @ x + np.array([0.2, -0.1, 7.0])

    corr = SecantCorrection(3, 2, min_step=0.004)
    for x in ([0.5, 0.5], [0.6, 0.5], [0.6, 0.3]):
        corr.observe(np.array(x), full(np.array(x)), simp)
    assert corr.n_updates == 2
    np.testing.assert_allclose(corr.jacobian, a, atol=1e-12)
    np.testing.assert_allclose(corr.correct(np.ones((3, 2))), a + 1.0, atol=1e-12)


def test_a_step_shorter_than_min_step_does_not_update_the_correction():
    corr = SecantCorrection(1, 2, min_step=0.004)
    corr.observe(np.array([0.5, 0.5]), np.array([0.0]), np.array([0.0]))
    # a 0.003 step (< 0.004) with a large change of the discrepancy: noise, not slope
    assert not corr.observe(np.array([0.503, 0.5]), np.array([1.0]), np.array([0.0]))
    assert corr.n_short_steps == 1 and np.all(corr.jacobian == 0.0)


def test_config_section_equals_code_defaults_and_bad_options_are_named():
    assert load_correction_options(str(CONFIG)) == CorrectionOptions()
    with pytest.raises(ValueError, match='method'):
        CorrectionOptions(method='kriging')
    with pytest.raises(ValueError, match='unknown correction option'):
        CorrectionOptions.from_mapping({'step': 0.1})


# A constrained quadratic whose "simplified model" has the constraint's slope half as
# steep as the full model's, as the scaled tyre-hop constraints at the ride optimum
# (slope ratio 1.3-2.2).  min |x - (0.3, 0.7)|^2 s.t. 2 (x1 + x2) - 1.6 <= 0: the
# projection onto x1 + x2 = 0.8 is x* = (0.2, 0.6), f* = 0.02 (hand calculation).
TARGET = np.array([0.3, 0.7])
X_STAR = np.array([0.2, 0.6])
OPTIONS = {'xtol': 1e-6, 'ftol': 1e-10, 'maxiter': 40, 'gtol': 1e-6,
           'surrogate_constraint_curvature': 'zero'}


def full_model(points):
    points = np.atleast_2d(points)
    f = np.sum((points - TARGET) ** 2, axis=1)
    g = np.column_stack([2.0 * (points.sum(axis=1) - 0.8), -np.ones(len(points))])
    return FullEvaluation(f=f, g=g)


def flat_simplified(x, inputs):
    # the objective's slope exact, the constraint's half the full model's; the values
    # at x follow the same (wrong) simplified model
    values = np.r_[np.sum((x - TARGET) ** 2), x.sum() - 0.8, -1.0]
    return 2.0 * (x - TARGET), np.array([[1.0, 1.0], [0.0, 0.0]]), values


@pytest.mark.parametrize('method', ['secant', 'none'])
def test_the_correction_makes_no_full_run_of_its_own(method):
    request = TuningRequest('ride', 2, x0=[0.9, 0.9], gradient_source='simplified',
                            options=OPTIONS, correction={'method': method})
    result = optimise(request, full_model, flat_simplified)
    # Section 2: one full run per evaluation, with or without the correction
    assert result.n_full_runs == result.nfev
    # 2n stencil runs and one at the iterate per gradient
    assert result.n_simplified_runs == 5 * result.ngev
    assert result.correction['method'] == method
    if method == 'secant':
        np.testing.assert_allclose(result.x_best, X_STAR, atol=1e-3)
        assert result.best_feasible and result.correction['n_updates'] >= 1
        # the learnt constraint row: the full slope 2 minus the simplified slope 1
        np.testing.assert_allclose(result.correction['jacobian'][1], [1.0, 1.0], atol=0.05)


def test_a_scenario_whose_objective_jumps_runs_without_the_correction():
    # config/optimiser.yaml off_for_scenarios: [mixed] (the valve controller's switch
    # pairs make the mixed objective jump).  The same problem posed as 'mixed' runs the
    # paper's eq. 25 gradients alone, and the result says why; 'ride' is corrected.
    assert not CorrectionOptions().applies_to('mixed')
    assert CorrectionOptions().applies_to('ride')
    assert not CorrectionOptions(method='none').applies_to('ride')
    assert CorrectionOptions(off_for_scenarios=[]).applies_to('mixed')
    with pytest.raises(ValueError, match='off_for_scenarios'):
        CorrectionOptions(off_for_scenarios='mixed')
    mixed = optimise(TuningRequest('mixed', 2, x0=[0.9, 0.9], gradient_source='simplified',
                                   options=OPTIONS), full_model, flat_simplified)
    assert mixed.correction == {'method': 'none', 'off_for_scenario': 'mixed'}
    ride = optimise(TuningRequest('ride', 2, x0=[0.9, 0.9], gradient_source='simplified',
                                  options=OPTIONS), full_model, flat_simplified)
    assert ride.correction['method'] == 'secant' and ride.correction['n_updates'] >= 1


def test_soft_tyre_hop_measure_by_hand():
    # w = 0.5 x 4000 N = 2000 N; samples 0, 1000, 2000, 4000 N count 1, 0.5, 0, 0:
    # mean 0.375, g = 10 (0.375 - 0.1) = 2.75; eq. 11 counts one sample in four:
    # 10 (0.25 - 0.1) = 1.5
    fz = np.array([[0.0, 1000.0, 2000.0, 4000.0]])
    assert soft_tyre_hop_constraints(fz, np.array([4000.0]), 0.5)[0] == pytest.approx(2.75)
    assert tyre_hop_constraints(fz, 0.002)[0] == pytest.approx(1.5)
    with pytest.raises(ValueError, match='load_fraction'):
        soft_tyre_hop_constraints(fz, np.array([4000.0]), 0.0)


def test_the_smooth_measure_has_a_slope_where_eq_11_is_flat():
    # At the 4-variable ride reference optimum, a 1e-4 step of the rear gas volume
    # leaves the pitch-plane model's eq. 11 count of the rear tyre unchanged (99 % of
    # such steps change nothing), while the smooth measure moves.
    x = np.array([0.248, 0.974, 0.312, 1.0])
    out = run_simplified('ride', np.array([x, x - [0.0, 0.0, 0.0, 1e-4]]), 4)
    assert out['g'][0, 2] == out['g'][1, 2]
    assert out['g_soft'][0, 2] != out['g_soft'][1, 2]


def test_an_extra_constraint_with_a_simplified_model_is_corrected_too():
    # min |x - (0.3, 0.7)|^2 s.t. f_other = x1 + x2 <= 0.8, where the other scenario's
    # simplified model has half the full slope (and the values to match).  The secant
    # learns the missing half on that row: x* = (0.2, 0.6) (hand, as above), and the
    # row's learnt correction is the full slope 1 minus the simplified 0.5.
    def own_model(points):
        points = np.atleast_2d(points)
        return FullEvaluation(f=np.sum((points - TARGET) ** 2, axis=1),
                              g=-np.ones((len(points), 4)), inputs={'x': points[0]})

    def own_gradient(x, inputs):
        return 2.0 * (x - TARGET), np.zeros((4, 2)), np.r_[np.sum((x - TARGET) ** 2),
                                                          -np.ones(4)]

    def other_model(points):
        points = np.atleast_2d(points)
        return FullEvaluation(f=points.sum(axis=1), g=-np.ones((len(points), 4)),
                              inputs={'x': points[0]})

    def other_gradient(x, inputs):
        return np.array([0.5, 0.5]), np.zeros((4, 2)), np.r_[0.5 * x.sum(), -np.ones(4)]

    request = TuningRequest('ride', 2, x0=[0.9, 0.9], gradient_source='simplified',
                            options=OPTIONS, constraints=[('handling', 'f_hand', 0.8)])
    result = optimise(request, own_model, own_gradient,
                      constraint_models={'handling': other_model},
                      constraint_gradients={'handling': other_gradient})
    np.testing.assert_allclose(result.x_best, X_STAR, atol=1e-3)
    assert result.n_full_runs == 2 * result.nfev  # one run of each scenario per iterate
    jac = np.asarray(result.correction['jacobian'])
    assert jac.shape == (6, 2)  # f, 4 eq. 11 rows, the extra constraint
    np.testing.assert_allclose(jac[5], [0.5, 0.5], atol=0.05)


BLIND_TARGET = np.array([0.3, 0.7])


def blind_full(points):
    """The full model: f = (x0 - 0.3)^2 + (x1 - 0.7)^2, one inactive constraint."""
    points = np.atleast_2d(points)
    return FullEvaluation(f=np.sum((points - BLIND_TARGET) ** 2, axis=1),
                          g=-np.ones((len(points), 1)))


def blind_simplified(x, inputs):
    """A simplified model that sees x0 only: its x1 column is exactly zero."""
    values = np.r_[(x[0] - 0.3) ** 2, -1.0]
    return np.array([2.0 * (x[0] - 0.3), 0.0]), np.zeros((1, 2)), values


def _run_blind(options, correction):
    """tuning.optimise on the blind problem from (0.9, 0.2)."""
    request = TuningRequest('ride', 2, x0=[0.9, 0.2], gradient_source='simplified',
                            options=options, correction=correction)
    return optimise(request, blind_full, blind_simplified)


def test_a_variable_the_simplified_model_cannot_see_is_seeded_and_then_moves():
    # the full model: f = (x0 - 0.3)^2 + (x1 - 0.7)^2; the simplified model sees x0 only
    # (a bar in the pitch-plane model: its column is exactly zero).  Without the seed
    # Dynamic-Q never steps along x1; with it x1 moves toward the full model's 0.7, for
    # one full run more.  It does not settle on 0.7: Broyden's update shares each mixed
    # step's change between the columns, and the run ends at the bound x1 = 1 with a
    # stale slope; the best design seen has x1 = 0.85 (docs/design_space.md)
    runs = {seed: _run_blind(OPTIONS, {'seed_blind': seed}) for seed in (True, False)}
    assert runs[True].correction['seeded_columns'] == [1]
    assert abs(runs[True].x_best[1] - 0.7) < 0.5 * abs(0.2 - 0.7)  # halfway there at least
    assert runs[True].f_best < 0.05 < runs[False].f_best  # 0.023 against 0.25 ((0.2-0.7)^2)
    assert runs[False].x_best[1] == pytest.approx(0.2)  # never moved
    # the seed's one full run (x1 + 0.1, seed_step) is counted
    assert runs[True].n_full_runs == runs[True].nfev + 1


class _Probes:
    """Full-model values f = (x0 - 0.7)^2 + x1, g = -1 of stepped designs, counted."""

    def __init__(self):
        self.runs = 0

    def stacked_values(self, points):
        points = np.atleast_2d(points)
        self.runs += len(points)
        return np.column_stack([(points[:, 0] - 0.7) ** 2 + points[:, 1],
                                -np.ones(len(points))])


def test_a_bound_the_correction_alone_decides_is_checked_with_one_full_run():
    # x0 sits on its lower bound 0.001.  The simplified slope of f along x0 points inward
    # (-1.0), the full model's too (2 (0.001 - 0.7) = -1.398), but a stale secant column
    # (+1.5) reverses it: the corrected slope +0.5 would make the bound look optimal.
    # One full run at x0 + 0.1 sets the column to the one-sided full difference
    # ((0.101 - 0.7)^2 - (0.001 - 0.7)^2) / 0.1 = -1.298 minus the simplified -1.0.
    x = np.array([0.001, 0.5])
    lower, upper = np.full(2, 0.001), np.ones(2)
    probes = _Probes()
    full = probes.stacked_values(x)[0]
    probes.runs = 0
    values = np.array([0.3, np.nan])  # g has no simplified model
    raw = np.array([[-1.0, 1.0], [0.0, 0.0]])
    corr = SecantCorrection(2, 2)
    corr.jacobian[0, 0] = 1.5
    verified = {}
    assert verify_bounds(corr, probes, x, full, values, raw, corr.correct(raw), 0.1,
                         lower, upper, verified)
    assert probes.runs == 1 and corr.seeded == [0]
    slope = ((0.101 - 0.7) ** 2 - (0.001 - 0.7) ** 2) / 0.1
    assert corr.correct(raw)[0, 0] == pytest.approx(slope)
    assert corr.jacobian[1, 0] == 0.0  # the row without a simplified model stays exact
    # a later secant reverses it again at the same design: set again, no new run
    corr.jacobian[0, 0] = 1.5
    assert verify_bounds(corr, probes, x, full, values, raw, corr.correct(raw), 0.1,
                         lower, upper, verified)
    assert probes.runs == 1 and corr.correct(raw)[0, 0] == pytest.approx(slope)
    # a slope the correction does not reverse, or an interior variable: no run
    assert not verify_bounds(corr, probes, x, full, values, raw, corr.correct(raw), 0.1,
                             lower, upper, verified)
    inner = np.array([0.3, 0.5])
    corr.jacobian[0, 0] = 1.5
    assert not verify_bounds(corr, probes, inner, full, values, raw, corr.correct(raw),
                             0.1, lower, upper, verified)
    assert probes.runs == 1
    # the same bound a seed step or more from the last check: checked again
    far = np.array([0.001, 0.35])
    assert verify_bounds(corr, probes, far, probes.stacked_values(far)[0], values, raw,
                         corr.correct(raw), 0.1, lower, upper, verified)
    assert probes.runs == 3  # the design's own run above, and the check's


def test_seeding_a_column_subtracts_the_simplified_slope():
    corr = SecantCorrection(2, 2)
    corr.seed_column(1, [0.5, 0.5], -0.1, [1.0, 2.0], [1.2, 2.0], [0.0, 0.0], [0.5, -3.0])
    # (1.2 - 1.0) / -0.1 - 0.5 = -2.5; (2.0 - 2.0) / -0.1 + 3.0 = 3.0
    np.testing.assert_allclose(corr.jacobian[:, 1], [-2.5, 3.0])


def test_a_run_that_ends_at_the_iteration_limit_restarts_once_from_its_answer():
    # The blind problem above with 3 iterations: the run ends at the limit with x1 at
    # 0.85, its column learnt at the start.  Started again from that answer, the
    # correction seeds x1's column there (one full run) and Dynamic-Q takes its first
    # move limit: x1 goes to 0.55 and f from 0.0234 to 0.0217, below the first answer's
    # (the answer of the restart is never worse: it starts there).
    options = dict(OPTIONS, maxiter=3)
    never = _run_blind(options, {'restarts': 0})
    once = _run_blind(options, {'restarts': 1})
    assert never.restarts == 0 and once.restarts == 1
    assert never.stop_test == once.stop_test == 'maxiter'
    assert once.f_best < never.f_best
    assert abs(once.x_best[1] - 0.7) < abs(never.x_best[1] - 0.7)
    # one history, numbered on; the first run's records come first
    assert [r['iteration'] for r in once.history] == list(range(len(once.history)))
    assert len(once.history) == 2 * len(never.history)
    np.testing.assert_allclose(once.history[len(never.history)]['x'], never.x_best)
    # the restart pays what the first run did (4 evaluations and 1 seed run) but the
    # answer it starts from, whose values are known, and 2 runs more: the first run's
    # Broyden estimate of x0's column (-0.37) is stale against the simplified slope
    # there (2 (0.29 - 0.3) = -0.02), so x0's column is set afresh by a central
    # difference (reseed_ratio); exact on this quadratic, it leaves the path unchanged
    assert once.correction['seeded_columns'] == [1, 0]
    assert once.n_full_runs == 2 * never.n_full_runs - 1 + 2
    with pytest.raises(ValueError, match='restarts'):
        CorrectionOptions(restarts=-1)


def test_a_run_that_stalls_in_f_while_still_stepping_restarts_after_the_ftol_test():
    # The blind problem with a loose ftol (1e-2) and xtol off (1e-9): the first run
    # stops by ftol with x1 at 0.85, its stale column learnt at the start.  Restarted
    # after the ftol test (restart_after's default), the correction seeds x1's column
    # at the answer and the run takes x1 to 0.55, f from 0.0234 to 0.0217 (the full
    # model's optimum is x1 = 0.7, f 0.0 + (x0 - 0.3)^2); without the ftol test in
    # restart_after the run stops at its first answer.
    options = dict(OPTIONS, ftol=1e-2, xtol=1e-9)
    kept = _run_blind(options, {'restart_after': ['maxiter']})
    restarted = _run_blind(options, {})
    assert kept.stop_test == 'ftol' and kept.restarts == 0
    assert restarted.restarts == 1 and restarted.restarted_after == ['ftol']
    assert restarted.message.endswith('(the run restarted 1 time(s) from its answer: '
                                      'after the ftol test)')
    assert restarted.f_best < kept.f_best
    assert abs(restarted.x_best[1] - 0.7) < abs(kept.x_best[1] - 0.7)
    assert CorrectionOptions().restart_after == ('maxiter', 'ftol')
    with pytest.raises(ValueError, match=r'restart_after must be a list of stop tests '
                                         r'\(maxiter, ftol, xtol, noise, rho_min, '
                                         r"bound_kkt\), got \['often'\]"):
        CorrectionOptions(restart_after=['often'])


def test_poorly_seen_variables_are_those_whose_learnt_slope_overrules_the_simplified_one():
    # objective row: the correction of x0 is 0.1 of its simplified slope, of x1 0.6 of
    # it (more than reseed_ratio 0.5), x2 is blind (seeded as such, not here), x3's
    # simplified slope is zero in f but not in g (seen: the objective's model says 0)
    previous = np.array([[0.1, 0.6, 0.5, 0.2], [0.0, 0.0, 0.0, 0.0]])
    simplified = np.array([[1.0, -1.0, 0.0, 0.0], [1.0, 1.0, 0.0, 1.0]])
    np.testing.assert_array_equal(poorly_seen(previous, simplified, 0.5), [1, 3])
    assert poorly_seen(previous, simplified, 0.0).size == 0  # 0: none
    with pytest.raises(ValueError, match='one 2-D shape'):
        poorly_seen(previous[:, :2], simplified, 0.5)
    with pytest.raises(ValueError, match='reseed_ratio must be finite and >= 0'):
        CorrectionOptions(reseed_ratio=-1.0)


def _run_dim(options, correction):
    """tuning.optimise from (0.9, 0.9) on a problem whose simplified model sees x1 dimly.

    Full model: f = (x0 - 0.3)^2 + (x1 - 0.7)^2; the simplified model gives x1 a tenth
    of the full model's slope (as the roll-and-pitch model gives an anti-roll bar half
    or less of the full model's slope in some rows, docs/design_space.md).
    """
    def dim(x, inputs):
        values = np.r_[(x[0] - 0.3) ** 2 + 0.1 * (x[1] - 0.7) ** 2, -1.0]
        return np.array([2.0 * (x[0] - 0.3), 0.2 * (x[1] - 0.7)]), np.zeros((1, 2)), values

    request = TuningRequest('ride', 2, x0=[0.9, 0.9], gradient_source='simplified',
                            options=options, correction=correction)
    return optimise(request, blind_full, dim)


def test_a_restart_sets_the_column_of_a_dimly_seen_variable_from_the_full_model():
    # With 4 iterations the first run stops at the limit.  Its secant, learnt along
    # diagonal steps, holds corrections larger than half the simplified slopes at the
    # answer in both columns (Broyden shares each step's change between them), so the
    # restart sets both by central differences (4 full runs, seed_step 0.1 each way:
    # exact on the quadratic) where with reseed_ratio 0 it starts from C = 0 and the
    # simplified tenth of x1's slope.  Measured: f 4e-5 at (0.301, 0.706) against
    # 1.4e-3 at (0.305, 0.738)
    options = dict(OPTIONS, maxiter=4)
    plain = _run_dim(options, {'reseed_ratio': 0.0})
    reseeded = _run_dim(options, {})
    assert plain.restarts == reseeded.restarts == 1
    assert plain.correction['seeded_columns'] == []
    assert reseeded.correction['seeded_columns'] == [0, 1]
    assert reseeded.n_full_runs == plain.n_full_runs + 4
    # the restart's answer: x1 nearer the full model's 0.7, f lower
    assert abs(reseeded.x_best[1] - 0.7) < abs(plain.x_best[1] - 0.7)
    assert reseeded.f_best < 0.1 * plain.f_best


def _wrong_sign(x, inputs):
    """A simplified model whose x1 slope has the wrong sign near the optimum.

    Its f is the full model's less x1 (slope 2 (x1 - 0.7) - 1: along the constraint it
    pulls x1 up, where the full model pulls it down, as the roll-and-pitch model does
    with the rear bar, docs/design_space.md); its g is the full model's, exact.
    """
    values = np.r_[(x[0] - 0.3) ** 2 + (x[1] - 0.7) ** 2 - x[1], x.sum() - 0.9]
    return np.array([2.0 * (x[0] - 0.3), 2.0 * (x[1] - 0.7) - 1.0]), np.ones((1, 2)), values


def test_a_continuation_on_the_check_model_keeps_the_poorly_seen_columns():
    # Full model f = (x0 - 0.3)^2 + (x1 - 0.7)^2, g = x0 + x1 - 0.9; the check's model
    # the same with g 0.05 higher, so the check refuses the first answer (0.25, 0.65)
    # and the run goes on on the check's model to its optimum (0.225, 0.625), f =
    # 2 x 0.075^2 = 0.01125 (hand calculation: (0.3, 0.7) projected on x0 + x1 = 0.85).
    # The discrepancy D = x1 is linear, and the first run's secant has learnt it; both
    # columns pass the poorly-seen test (Broyden shares a step's change between them)
    # and are kept (carry_to_check): the continuation steps straight to the optimum (2
    # evaluations).  Started at C = 0 it first follows the simplified slope up the
    # boundary to (0.014, 0.836), f 0.1, and pays 2 runs more to learn D back.
    def full(points):
        p = np.atleast_2d(points)
        return FullEvaluation(f=np.sum((p - BLIND_TARGET) ** 2, axis=1),
                              g=(p.sum(axis=1) - 0.9)[:, None])

    def check_model(points):
        run = full(points)
        return FullEvaluation(f=run.f, g=run.g + 0.05)

    runs = {}
    for carry in (False, True):
        request = TuningRequest('ride', 2, x0=[0.9, 0.9], gradient_source='simplified',
                                options=OPTIONS, correction={'carry_to_check': carry})
        runs[carry] = optimise(request, full, _wrong_sign, check_model=check_model,
                               check_gtol=1e-6, check_continue_by='tighter_model')
    for result in runs.values():
        assert result.check['continued'] and result.stop_test == 'xtol'
        np.testing.assert_allclose(result.x_best, [0.225, 0.625], atol=1e-4)
        assert result.f_best == pytest.approx(0.01125, rel=1e-3)
    assert runs[True].correction['carried_columns'] == [0, 1]
    assert runs[False].correction['carried_columns'] == []
    assert runs[True].n_full_runs == runs[False].n_full_runs - 2
    later = [r['x'] for r in runs[False].history[runs[False].check['first_iteration']:]]
    assert later[1][1] > 0.8  # without: x1 up first, against the full model
    with pytest.raises(ValueError, match='carry_to_check must be true or false, got 1'):
        CorrectionOptions(carry_to_check=1)
