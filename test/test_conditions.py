"""Operating conditions (suspension_tuning.conditions): a condition set is checked when it
is read, in one line naming the file, the condition and the key; a payload moves the
static loads as statics says; a condition set is optimised as a worst case or a weighted
mean (suspension_tuning.tuning.optimise_conditions)."""

import math
from pathlib import Path

import numpy as np
import pytest

from suspension_tuning.conditions import (
    Condition,
    ConditionError,
    ConditionSet,
    condition_scenarios,
    load_conditions,
    payload_limits,
    with_payload,
)
from suspension_tuning.tuning import (
    FullEvaluation,
    TuningRequest,
    optimise_conditions,
)
from suspension_tuning.vehicle.params import load_vehicle_params
from suspension_tuning.vehicle.strut import static_pressure_pa

GOOD = """conditions:
  - name: slow
    speed_kmh: 30.0
    payload: {mass_kg: 0.0}
  - name: laden
    speed_kmh: 50.0
    payload: {mass_kg: 300.0, behind_front_axle_m: 2.5}
    road: belgian_paving
    weight: 2.0
"""


def _write(tmp_path, text):
    path = tmp_path / 'conditions.yaml'
    path.write_text(text)
    return path


def test_the_shipped_condition_set_is_three_speeds_unladen_and_laden():
    conditions = load_conditions()
    assert conditions.names == ['unladen_30', 'unladen_50', 'unladen_70',
                                'laden_30', 'laden_50', 'laden_70']
    assert sorted({c.speed_kmh for c in conditions.conditions}) == [30.0, 50.0, 70.0]


def test_a_condition_set_round_trips_through_its_text(tmp_path):
    conditions = load_conditions(_write(tmp_path, GOOD))
    assert ConditionSet.from_text(conditions.as_text()) == conditions
    assert conditions.weights == pytest.approx([1 / 3, 2 / 3])  # weights 1 and 2
    assert Condition.from_text(conditions.conditions[1].as_text()) == conditions.conditions[1]


@pytest.mark.parametrize('old, new, expected', [
    ('road: belgian_paving', 'road: cobbles_of_atlantis',
     "condition 'laden': road: "),
    ('mass_kg: 300.0', 'mass_kg: 700.0',
     "condition 'laden': payload.mass_kg: 700 kg is outside 0-650 kg"),
    ('behind_front_axle_m: 2.5', 'behind_front_axle_m: 4.5',
     "condition 'laden': payload.behind_front_axle_m: 4.5 m is outside the load space"),
    ('speed_kmh: 50.0', 'speed_kmh: 150.0',
     "condition 'laden': speed_kmh: 150 km/h is above the vehicle's top speed 132"),
    ('speed_kmh: 50.0', 'speed_kmh: 100.0',
     "condition 'laden': speed_kmh: the vehicle cannot hold 100 km/h over the run"),
    ('weight: 2.0', 'weight: -1.0', "condition 'laden': weight: must be a number >= 0"),
    ('speed_kmh: 50.0', 'speed_kmh: fast', "condition 'laden': speed_kmh: expected a number"),
])
def test_a_bad_condition_is_refused_naming_file_condition_and_key(tmp_path, old, new,
                                                                  expected):
    # 650 kg: gross vehicle mass 3050 kg less the 2400 kg vehicle (config/vehicle.yaml);
    # 100 km/h: 3 s settling + 375 m of averaging need 461 m of the 450 m road
    path = _write(tmp_path, GOOD.replace(old, new))
    with pytest.raises(ConditionError) as error:
        load_conditions(path)
    assert str(error.value).startswith(f'{path}: {expected}'), str(error.value)


def test_an_empty_set_and_weights_summing_to_zero_are_refused(tmp_path):
    with pytest.raises(ConditionError, match=r'conditions: the set is empty'):
        load_conditions(_write(tmp_path, 'conditions: []\n'))
    zero = GOOD.replace('weight: 2.0', 'weight: 0.0').replace(
        '    payload: {mass_kg: 0.0}\n', '    payload: {mass_kg: 0.0}\n    weight: 0.0\n')
    with pytest.raises(ConditionError, match=r'conditions: the weights sum to 0'):
        load_conditions(_write(tmp_path, zero))


def test_a_payload_moves_the_static_loads_as_statics_says():
    params = load_vehicle_params()
    mass, position = 650.0, 2.9
    laden = with_payload(params, mass, position)
    g = params.g_mps2
    # the four tyres carry the whole vehicle, payload included
    total = 2 * (laden.static_tyre_load_front_n + laden.static_tyre_load_rear_n)
    assert total == pytest.approx((params.mass_total_kg + mass) * g, rel=1e-12)
    # moments about the front axle: the rear struts carry sprung weight x a / L
    rear_gain = 2 * (laden.static_strut_load_rear_n - params.static_strut_load_rear_n)
    assert rear_gain == pytest.approx(mass * g * position / params.wheelbase_m, rel=1e-12)
    # the gas spring's static pressure follows: (p - p_atm) A_p = static strut load
    p_rear = static_pressure_pa(laden.static_strut_load_rear_n, laden)
    assert (p_rear - params.strut.atmospheric_pressure_pa) * params.strut.piston_area_m2 \
        == pytest.approx(laden.static_strut_load_rear_n)
    # the seats stay where they are on the body
    assert laden.a_m - laden.driver_x_m == pytest.approx(params.a_m - params.driver_x_m)
    assert with_payload(params, 0.0, 2.0) is params


def test_a_condition_keeps_the_configured_averaging_distance():
    ride = condition_scenarios(Condition('fast', 70.0))['ride']
    # 30 s at 50 km/h with 3 s settling: 27 s of averaging = 375 m; at 70 km/h 19.29 s
    assert ride['duration_s'] == pytest.approx(3.0 + 27.0 * 50.0 / 70.0)
    assert payload_limits()['max_mass_kg'] == pytest.approx(650.0)


# ----------------------------------------------------------------- the optimisation
CENTRES = {'a': np.array([0.2, 0.3]), 'b': np.array([0.8, 0.5])}


def _bowl_model(designs, conditions):
    """f_c = |x - centre_c|^2, no tyre hop (g = -1): an analytic minimax problem."""
    out = []
    for condition in conditions:
        d = np.atleast_2d(designs) - CENTRES[condition.name]
        out.append(FullEvaluation(f=np.sum(d ** 2, axis=1), g=-np.ones((len(d), 4)),
                                  metric_names=['dist_m'],
                                  metrics=np.sqrt(np.sum(d ** 2, axis=1))[:, None]))
    return out


def _bowl_set(weight_b=1.0):
    return ConditionSet((Condition('a', 30.0), Condition('b', 50.0, weight=weight_b)), 'test')


def _bowl_request(monkeypatch, conditions, form='worst', source='full', **kwargs):
    """A 2-variable ride request over ``conditions`` (read from the goal's text as set)."""
    monkeypatch.setattr(ConditionSet, 'from_text', staticmethod(lambda text: conditions))
    return TuningRequest('ride', 2, gradient_source=source, conditions='set',
                         condition_form=form, options={'maxiter': 40}, **kwargs)


def test_the_worst_case_form_finds_the_minimax_design(monkeypatch):
    conditions = _bowl_set()
    request = _bowl_request(monkeypatch, conditions, 'worst')
    result = optimise_conditions(request, _bowl_model)
    # the minimax of two equal bowls lies halfway between their centres, f = |d/2|^2
    half = 0.5 * (CENTRES['a'] + CENTRES['b'])
    assert result.x_best == pytest.approx(half, abs=2e-3)
    assert result.f_best == pytest.approx(np.sum((CENTRES['b'] - half) ** 2), rel=1e-2)
    assert result.condition_names == ['a', 'b']
    assert len(result.condition_metrics_best) == 2
    assert result.condition_metrics_best[0]['dist_m'] == pytest.approx(
        math.sqrt(result.condition_f_best[0]))
    # every design runs in both conditions, counted per condition; a round is one batch
    # (a design's runs, or the 2n central-difference designs' runs)
    assert result.n_full_runs % 2 == 0
    assert result.rounds < result.n_full_runs / 2


def test_the_weighted_mean_form_finds_the_weighted_centre(monkeypatch):
    conditions = _bowl_set(weight_b=3.0)
    request = _bowl_request(monkeypatch, conditions, 'mean')
    result = optimise_conditions(request, _bowl_model)
    # the minimum of 1/4 |x - a|^2 + 3/4 |x - b|^2 is the weighted mean of the centres
    centre = 0.25 * CENTRES['a'] + 0.75 * CENTRES['b']
    assert result.x_best == pytest.approx(centre, abs=2e-3)
    assert result.worst_condition == 'a'  # farther from the weighted centre


OFFSET = {'a': 0.0, 'b': 0.1}  # the 'metric' of the constraint test: x_1 + offset_c


def _bowl_model_with_metric(designs, conditions):
    """The bowls, with a_rms_driver_mps2 = x_1 + OFFSET[c] standing for a ride metric."""
    out = _bowl_model(designs, conditions)
    for condition, run in zip(conditions, out):
        run.metric_names = ['a_rms_driver_mps2']
        run.metrics = (np.atleast_2d(designs)[:, 0] + OFFSET[condition.name])[:, None]
    return out


def test_an_extra_constraint_on_a_metric_holds_in_every_condition(monkeypatch):
    conditions = _bowl_set()
    request = _bowl_request(monkeypatch, conditions, 'worst',
                            constraints=['ride:a_rms_driver_mps2<=0.4'])
    result = optimise_conditions(request, _bowl_model_with_metric)
    # x_1 + 0.1 <= 0.4 binds in condition b: x_1 = 0.3; then b's bowl is the worse one
    # everywhere near, so x_2 sits at b's centre 0.5 and f = (0.8 - 0.3)^2 = 0.25
    assert result.best_feasible
    assert result.x_best == pytest.approx([0.3, 0.5], abs=2e-3)
    assert result.f_best == pytest.approx(0.25, rel=1e-2)
    # the largest value over the conditions is the reported one; each condition's too
    assert result.constraint_values_best == pytest.approx([0.4], abs=2e-3)
    np.testing.assert_allclose(result.condition_constraint_values_best, [[0.3, 0.4]],
                               atol=2e-3)
    assert result.constraint_gradient_sources == ['full']
    # g: 4 tyre-hop rows per condition, then one row per condition of the constraint
    assert len(result.g_best) == 4 * 2 + 2


def test_an_extra_constraint_on_the_objective_takes_the_simplified_gradient(monkeypatch):
    conditions = _bowl_set(weight_b=3.0)

    def exact(name):  # the bowls' own gradient stands in for a scaled simplified one
        return lambda x, _inputs: (2.0 * (np.asarray(x) - CENTRES[name]), np.zeros((4, 2)),
                                   None)

    request = _bowl_request(monkeypatch, conditions, 'mean', 'simplified',
                            constraints=['ride:f_ride<=0.16'])
    result = optimise_conditions(request, _bowl_model,
                                 {name: exact(name) for name in ('a', 'b')})
    # the weighted centre (0.65, 0.45) has f_a = 0.225 > 0.16: the answer lies on the
    # circle |x - a| = 0.4, on the line from a to b: a + 0.4 (b - a) / |b - a|
    unit = (CENTRES['b'] - CENTRES['a']) / np.linalg.norm(CENTRES['b'] - CENTRES['a'])
    expected = CENTRES['a'] + 0.4 * unit
    assert result.best_feasible
    assert result.x_best == pytest.approx(expected, abs=3e-3)
    assert result.condition_f_best[0] == pytest.approx(0.16, abs=1e-3)
    assert result.constraint_gradient_sources == ['simplified']
    assert result.n_simplified_runs > 0 and result.n_full_runs % 2 == 0


def test_a_constraint_on_another_scenario_is_refused_with_a_condition_set(monkeypatch):
    monkeypatch.setattr(ConditionSet, 'from_text', staticmethod(lambda text: _bowl_set()))
    with pytest.raises(ValueError, match=r"constraint handling:f_hand<=0\.8: with a "
                                         r"condition set, a constraint bounds a ride"):
        TuningRequest('ride', 2, conditions='set', constraints=['handling:f_hand<=0.8'])


# ------------------------------------------------------------------ handling conditions
def test_a_condition_drives_the_lane_change_at_its_manoeuvre_speed_with_its_payload():
    from suspension_tuning import evaluation
    from suspension_tuning.conditions import condition_scenarios
    from suspension_tuning.vehicle.params import load_scenarios_config
    from suspension_tuning.vehicle.scenarios import run_scenario

    x = np.array([[0.5, 0.5, 0.5, 0.5]])
    condition = Condition('laden_50', 50.0, 650.0, 2.9, '', 1.0, manoeuvre_speed_kmh=50.0)
    run = evaluation.evaluate('handling', x, condition=condition.as_text())
    # the same run by hand: config/scenarios.yaml with handling.speed_kmh 50, the payload
    config = load_scenarios_config()
    config['handling']['speed_kmh'] = 50.0
    assert condition_scenarios(condition)['handling'] == config['handling']
    by_hand = run_scenario('handling', x, with_payload(load_vehicle_params(), 650.0, 2.9),
                           config=config)
    assert run.f[0] == by_hand.f[0]
    # the lane change is laid out in metres: at 50 km/h it takes 65/50 of the 65 km/h time
    speed = float(np.mean(run.result.histories['speed_mps'][0]))
    assert speed == pytest.approx(50.0 / 3.6, rel=0.02)
    # a condition without a manoeuvre speed leaves the configured 65 km/h (and its text)
    plain = Condition('unladen', 50.0)
    assert 'manoeuvre_speed_kmh' not in plain.as_dict()
    assert condition_scenarios(plain)['handling'] == load_scenarios_config()['handling']


def test_a_manoeuvre_speed_above_the_top_speed_is_refused(tmp_path):
    path = _write(tmp_path, 'conditions:\n  - name: fast\n    speed_kmh: 50.0\n'
                            '    manoeuvre_speed_kmh: 150.0\n')
    with pytest.raises(ConditionError, match=r"condition 'fast': manoeuvre_speed_kmh: 150 "
                                             r"km/h is above the vehicle's top speed"):
        load_conditions(path)


def test_the_handling_over_two_conditions_improves_both_with_simplified_gradients(tmp_path):
    from suspension_tuning.evaluation import (
        in_process_condition_gradients,
        in_process_condition_model,
    )

    conditions = load_conditions(
        Path(__file__).parents[1] / 'config' / 'conditions_handling.yaml')
    pair = ConditionSet(tuple(c for c in conditions.conditions
                              if c.name in ('unladen_50', 'laden_65')), 'test')
    request = TuningRequest('handling', 2, conditions=pair.as_text(), condition_form='worst',
                            options={'maxiter': 4})
    # 4 eq. 25 samples per condition: the corners of the 2-variable box
    gradients = in_process_condition_gradients(pair, 2, str(tmp_path), n_samples=4,
                                               scenario='handling')
    result = optimise_conditions(request, in_process_condition_model(scenario='handling'),
                                 gradients)
    assert result.best_feasible
    start = in_process_condition_model(scenario='handling')(
        np.atleast_2d(request.start), pair.conditions)
    f_start = [float(run.f[0]) for run in start]
    # the worst condition is the laden one at 65 km/h (more roll: 4.9 deg first peak at
    # the baseline against 2.5 deg unladen at 50 km/h), and the optimisation lowers it
    assert result.worst_condition == 'laden_65'
    assert max(result.condition_f_best) < max(f_start)
    assert result.n_simplified_runs > 0


def test_the_answer_over_a_set_is_checked_at_the_tighter_tolerance_in_every_condition(
        monkeypatch):
    from suspension_tuning.tuning import check_summary

    conditions = _bowl_set()
    request = _bowl_request(monkeypatch, conditions, 'worst')

    def tighter(designs, conditions):  # a check that finds condition b's g 0.5 higher
        out = _bowl_model(designs, conditions)
        for condition, run in zip(conditions, out):
            run.g = run.g + (0.5 if condition.name == 'b' else 0.0)
        return out

    plain = optimise_conditions(request, _bowl_model)
    result = optimise_conditions(request, _bowl_model, check_model=tighter, check_gtol=5e-3)
    check = result.check
    # C = 2 more paid full runs than the same run unchecked
    assert result.n_full_runs == plain.n_full_runs + 2
    assert check['feasible_run'] and check['feasible_check']  # -1 + 0.5 <= 0
    assert check['condition_max_g_check'] == pytest.approx([-1.0, -0.5])
    assert check['condition_f_check'] == pytest.approx(result.condition_f_best)
    assert check['offset'] == pytest.approx([0.0] * 4 + [0.5] * 4)
    assert check == {**check, **check_summary(result.g_best, np.r_[-np.ones(4),
                                                                  -0.5 * np.ones(4)],
                                              max(result.condition_f_best), 5e-3)}


def test_an_answer_infeasible_at_the_check_is_continued_with_shifted_constraints(
        monkeypatch):
    conditions = _bowl_set()
    request = _bowl_request(monkeypatch, conditions, 'worst')

    def limited(offset):
        """The bowls with x_1 <= 0.5 - offset in condition b (each tyre-hop row)."""
        def model(designs, conditions):
            out = _bowl_model(designs, conditions)
            for condition, run in zip(conditions, out):
                if condition.name == 'b':
                    x1 = np.atleast_2d(designs)[:, 0]
                    run.g = np.repeat((x1 - 0.5 + offset)[:, None], 4, axis=1)
            return out
        return model

    # the run's model allows x_1 <= 0.5, the tighter check only x_1 <= 0.4
    result = optimise_conditions(request, limited(0.0), check_model=limited(0.1),
                                 check_gtol=5e-3, check_continuations=2)
    check = result.check
    assert not check['first']['feasible_check'] and check['first']['feasible_run']
    assert check['continued'] and check['continuations'] == 1
    assert check['shift'][4:8] == pytest.approx([0.1] * 4, abs=2e-3)  # b's rows
    assert check['feasible_check']
    # the minimax with x_1 <= 0.4: b's bowl is the worse one, x_2 at its centre 0.5,
    # f = (0.8 - 0.4)^2 = 0.16 (the unshifted answer, halfway between the centres at
    # (0.5, 0.4), had f = 0.3^2 + 0.1^2 = 0.10)
    np.testing.assert_allclose(result.x_best, [0.4, 0.5], atol=3e-3)
    assert result.f_best == pytest.approx(0.16, abs=3e-3)
    # the continued run's records follow the first run's
    iterations = [rec['iteration'] for rec in result.history]
    assert iterations == sorted(iterations) and 'shift' in result.history[-1]
    # without continuations left: the answer stays, infeasible at the check, and says so
    plain = optimise_conditions(request, limited(0.0), check_model=limited(0.1),
                                check_gtol=5e-3)
    assert not plain.check['feasible_check'] and not plain.check['continued']
    assert 'no continuation' in plain.check['not_continued']
    np.testing.assert_allclose(plain.x_best, [0.5, 0.4], atol=3e-3)


def test_a_corrected_run_at_the_iteration_limit_restarts_once_from_its_answer(monkeypatch):
    # simplified_correction.restarts, as for one condition (test_correction): a run over
    # a set whose corrections engaged (the gradients give simplified values) and that
    # reached maxiter starts once more from its answer.  The simplified model is each
    # bowl at half its slope (values f_c / 2), so the correction has a slope to learn.
    conditions = _bowl_set()

    def half(name):
        def gradient(x, _inputs):
            d = np.asarray(x, float) - CENTRES[name]
            return d, np.zeros((4, 2)), np.r_[0.5 * float(d @ d), -np.ones(4)]
        return gradient

    gradients = {name: half(name) for name in ('a', 'b')}
    results = {}
    for restarts in (0, 1):
        monkeypatch.setattr(ConditionSet, 'from_text', staticmethod(lambda text: conditions))
        request = TuningRequest('ride', 2, gradient_source='simplified', conditions='set',
                                condition_form='worst', options={'maxiter': 3},
                                correction={'restarts': restarts})
        results[restarts] = optimise_conditions(request, _bowl_model, gradients)
    assert results[0].restarts == 0 and results[0].nit == 3
    once = results[1]
    assert once.restarts == 1 and 'restarted 1 time(s)' in once.message
    assert once.nit == 6  # two runs of 3 iterations, the history numbered on
    assert [r['iteration'] for r in once.history] == list(range(len(once.history)))
    # the second run starts at the first run's answer (its first record, after the first
    # run's start and 3 iterations) and the answer is the best of both runs
    first = results[0]
    np.testing.assert_array_equal(once.history[4]['x'], first.x_best)
    assert once.f_best <= first.f_best
