"""The passive suspension, its ride-handling Pareto front, the switched 4S4, and the
constrained in-process runs the front is made of (recorded and resumed)."""

import json

import numpy as np
import pytest

from suspension_tuning import evaluation
from suspension_tuning.studies import pareto
from suspension_tuning.vehicle.mixed import run_mixed
from suspension_tuning.vehicle.params import load_vehicle_params
from suspension_tuning.vehicle.passive import passive_setting, switched_setting
from suspension_tuning.vehicle.valve_logic import HANDLING_STATE, RIDE_STATE

# A soft, lightly damped 4-variable design: f and the metrics of the mixed run depend
# on every setting through the whole run (paving and lane change).
DESIGN = np.array([[0.3, 0.8, 0.4, 0.7]])


def locked(state):
    return [lambda step, vehicle_state: state]


def mixed_values(result):
    # f, g and the vehicle's metrics; the valve bookkeeping (switches, share of time in
    # the handling state) differs between valve states by design.
    vehicle = [np.ravel(v) for k, v in result.metrics.items()
               if k not in ('valve_switches', 'handling_state_fraction')]
    return np.concatenate([result.f, np.ravel(result.g), *vehicle])


def test_a_passive_setting_is_the_same_suspension_in_every_valve_state():
    # Equal gas volumes and damper factors in both states: the empty large accumulator
    # has K = 0, so connecting it changes neither volume nor pressure; the whole mixed
    # run (paving and lane change) gives the same bits in the ride and handling states.
    setting = passive_setting(DESIGN)
    ride = run_mixed(DESIGN, locked(RIDE_STATE), setting=setting)
    handling = run_mixed(DESIGN, locked(HANDLING_STATE), setting=setting)
    np.testing.assert_array_equal(mixed_values(ride), mixed_values(handling))
    switching = run_mixed(DESIGN, setting=setting)  # the valve controller switching
    np.testing.assert_array_equal(mixed_values(switching), mixed_values(ride))


@pytest.mark.parametrize('scenario', ['ride', 'handling'])
def test_each_scenario_sees_the_passive_design_as_its_own_state(scenario):
    # The 'ride' scenario uses only the soft volume and low dpsf, 'handling' only the
    # stiff volume and high dpsf: the scenario's own run (its private runner, with the
    # setting swapped) gives the same bits for the passive setting of x as for the
    # scenario's setting of x, so the passive front is the front of the two scenario
    # objectives over one shared x.
    from suspension_tuning.vehicle import scenarios
    from suspension_tuning.vehicle.params import load_scenarios_config

    params, cfg = load_vehicle_params(), load_scenarios_config()
    own = scenarios.run_scenario(scenario, DESIGN)
    setting = passive_setting(DESIGN)
    if scenario == 'ride':
        passive = scenarios._run_ride(DESIGN, setting, params, cfg['ride'],
                                      cfg['handling']['speed_controller'])
    else:
        passive = scenarios._run_handling(DESIGN, setting, params, cfg['handling'])
    np.testing.assert_array_equal(passive.f, own.f)
    np.testing.assert_array_equal(passive.g, own.g)


def test_switched_setting_caps_a_stiff_volume_above_the_soft_one():
    # x = 0.2 -> 0.2 L, x = 0.8 -> 0.5 L (eq. 4 over 0.1-0.6 L): the small accumulator
    # alone cannot hold more gas than both together, so the handling volume is capped.
    setting, capped = switched_setting(np.array([0.5, 0.2]), np.array([1.0, 0.8]))
    assert setting.gas_volume_soft_m3[0, 0] == pytest.approx(0.2e-3)
    assert setting.gas_volume_stiff_m3[0, 0] == pytest.approx(0.2e-3)
    assert capped.tolist() == [[True, True]]
    assert setting.dpsf_high[0, 0] == pytest.approx(3.0)  # x = 1 -> dpsf 3 (eq. 4)


def test_non_dominated_keeps_only_points_no_other_beats_in_both():
    # (1, 3), (2, 2), (3, 1) trade off; (2.5, 2.5) is beaten by (2, 2); (3, 1) repeated.
    values = [[1, 3], [2, 2], [2.5, 2.5], [3, 1], [3, 1]]
    assert pareto.non_dominated(values).tolist() == [True, True, False, True, False]


def test_gap_is_the_share_of_the_achievable_improvement_lost():
    # f_opt = 0.2, f_baseline = 1.0: f = 0.6 loses half the possible 0.8 improvement.
    assert pareto.gap_pct(0.6, 0.2, 1.0) == pytest.approx(50.0)
    assert pareto.best_compromise([[10, 90], [40, 45], [80, 5]]) == 1  # max 45 smallest
    with pytest.raises(ValueError, match='f_baseline'):
        pareto.gap_pct(0.6, 0.2, 0.2)


def test_metric_names_of_the_constraints_are_those_the_scenarios_report():
    x = np.full((1, 2), 0.5005)
    for scenario in evaluation.scenarios():
        names = tuple(evaluation.evaluate(scenario, x).metric_names)
        assert names == evaluation.METRIC_NAMES[scenario]


@pytest.fixture(scope='module')
def quick_study(tmp_path_factory):
    # 2 variables, 2 eps values, 8 calibration samples (the 2^2 corners plus 4 LHS
    # points): a smoke-sized study; the figures of docs/pareto.md come from the full one.
    out = tmp_path_factory.mktemp('pareto')
    return out, pareto.run_pareto(out, n_vars=2, n_points=2, calibration_samples=8,
                                  log=lambda _: None)


def test_the_passive_front_is_non_dominated_and_respects_its_bounds(quick_study):
    _, study = quick_study
    points = {p['name']: p for p in study['points']}
    front = [points[name] for name in study['front']]
    assert len(front) >= 2
    for a in front:
        for b in front:
            assert not (b['f_ride'] < a['f_ride'] and b['f_hand'] < a['f_hand'])
    gtol = 1e-3  # config/optimiser.yaml vehicle gtol
    for p in front:
        if p['kind'] == 'front':
            assert p['f_hand'] <= p['eps'] + gtol  # full-model value within the bound
    # The end points are the single-objective optima: zero gap in their own objective.
    assert points['ride_optimum']['gap_ride_pct'] == 0.0
    assert points['handling_optimum']['gap_hand_pct'] == 0.0
    assert points['baseline']['gap_ride_pct'] == pytest.approx(100.0)


def test_the_study_writes_json_plot_table_and_a_bag_per_run(quick_study):
    from suspension_tuning.bag.reader import read_messages

    out, study = quick_study
    payload = json.loads((out / 'pareto.json').read_text())
    assert payload['figures'] == study['figures']
    assert (out / 'pareto.png').stat().st_size > 0
    assert '| design |' in (out / 'pareto.md').read_text()
    assert len(study['bags']) == len(study['runs'])
    front_run = next(r for r in study['runs'] if r['name'].startswith('front_0'))
    assert front_run['details']['constraint_gradient_sources'] == ['simplified'] * 5
    contents = read_messages(front_run['bag'])
    assert len(contents.on('/optimisation/progress')) == len(front_run['history'])
    assert len(contents.on('/optimisation/result')) == 1
    # The closed loop keeps the ride optimum's ride on the paving when it does not switch
    # there, and is never worse in handling than the ride state held through the run.
    closed = study['switched']['closed_loop']
    mixed = {p['name']: p for p in study['mixed']}
    assert closed['f_hand'] < mixed['ride_optimum']['f_hand']


def test_a_constrained_run_resumes_from_its_bag_with_its_constraints(tmp_path):
    # Two iterations recorded, resumed to five: the iterates of an uninterrupted
    # five-iteration run (deterministic model and optimiser; the bag's run
    # configuration carries the extra constraint).
    from suspension_tuning.resume import resume
    from suspension_tuning.studies.common import run_dynamic_q, vehicle_options, write_bag

    spec = ['handling:f_hand<=1.2']  # active: the ride optimum has f_hand ~1.8
    short, recorder = run_dynamic_q('ride', 2, 'centre', 'full',
                                    options=vehicle_options() | {'maxiter': 2},
                                    constraints=spec)
    bag = write_bag(tmp_path / 'short', short, recorder)
    resumed = resume(bag, max_iterations=5)
    straight, _ = run_dynamic_q('ride', 2, 'centre', 'full',
                                options=vehicle_options() | {'maxiter': 5},
                                constraints=spec, record=False)
    np.testing.assert_array_equal(resumed.x, straight.x)
    assert resumed.nit == straight.iterations
    assert resumed.constraint_values == straight.details['constraint_values']
