"""A goal over a set of operating conditions, through the graph.

Three conditions (50 km/h unladen and laden, 70 km/h unladen): the coordinator
calibrates each condition's simplified model in it, sends a design's runs in every
condition as one batch, and reports per condition the objective and the physical
metrics of the reported design and of the baseline, with the worst condition; the bag
records the condition set and the result.
"""

import numpy as np
import pytest
from rclpy.parameter import Parameter

pytestmark = pytest.mark.ros

SAMPLES = 4  # eq. 25 samples per condition: the 4 corners of the 2-variable box
NAMES = ['unladen_50', 'laden_50', 'unladen_70']


@pytest.fixture
def graph(ros_context, tmp_path):
    from rclpy.node import Node

    from suspension_tuning.graph import SpinningGraph, build_nodes

    topics = ['/optimisation/run_config', '/optimisation/progress', '/optimisation/result']
    nodes = build_nodes(workers=1, record=True, context=ros_context, overrides={
        'gradient_evaluator': [Parameter('calibration_dir', value=str(tmp_path))],
        'coordinator': [Parameter('calibration_samples', value=SAMPLES),
                        Parameter('final_telemetry', value=False)],
        'recorder': [Parameter('output_dir', value=str(tmp_path / 'bags')),
                     Parameter('topics', value=topics), Parameter('post_run_s', value=0.2)]})
    client_node = Node('conditions_client', context=ros_context)
    spinning = SpinningGraph(nodes, [client_node])
    try:
        yield nodes, client_node
    finally:
        spinning.shutdown()


def _run(client_node, goal):
    from rclpy.action import ActionClient
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.nodes._spin import wait_future

    client = ActionClient(client_node, Optimise, '/coordinator/optimise')
    assert client.wait_for_server(timeout_sec=10.0)
    handle = wait_future(client.send_goal_async(goal), 30.0)
    return wait_future(handle.get_result_async(), 300.0).result


def test_a_three_condition_goal_reports_every_condition_in_the_result_and_the_bag(graph,
                                                                                  tmp_path):
    import time

    import yaml
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning import evaluation
    from suspension_tuning.bag.reader import decode, read_messages
    from suspension_tuning.conditions import ConditionSet, load_conditions
    from suspension_tuning.inspect_bag import _format, summary, write_plots
    from suspension_tuning.nodes._conditions import CONDITION_METRICS as BY_SCENARIO
    from suspension_tuning.nodes.recorder import RecorderNode
    from suspension_tuning.physical_metrics import physical_metrics
    from suspension_tuning.tune import format_result
    from suspension_tuning.vehicle.design import load_design_space

    CONDITION_METRICS = BY_SCENARIO['ride']
    nodes, client_node = graph
    shipped = load_conditions()
    conditions = ConditionSet(tuple(c for name in NAMES for c in shipped.conditions
                                    if c.name == name), 'test')
    result = _run(client_node, Optimise.Goal(
        scenario='ride', n_vars=2, gradient_source='simplified', max_iterations=3,
        conditions=conditions.as_text(), condition_form='worst'))
    assert len(result.x) == 2, result.message
    assert list(result.condition_names) == NAMES
    assert result.n_calibration_runs == 3 * SAMPLES  # each condition calibrated in it
    assert result.n_full_runs % 3 == 0  # a design runs in the 3 conditions
    assert 0 < result.n_rounds <= result.n_full_runs // 3
    # The reported design and the baseline in each condition, in-process: the same bits.
    k = len(CONDITION_METRICS)
    x_base = load_design_space().baseline_x(2)
    for c, condition in enumerate(conditions.conditions):
        for x, f_field, metrics_field in ((result.x, 'condition_f', 'condition_metrics'),
                                          (x_base, 'condition_baseline_f',
                                           'condition_baseline_metrics')):
            run = evaluation.evaluate('ride', np.asarray(x)[None, :],
                                      condition=condition.as_text())
            assert getattr(result, f_field)[c] == run.f[0]
            shown = physical_metrics('ride', run.metric_names, run.metrics[0])
            assert list(getattr(result, metrics_field)[c * k:(c + 1) * k]) == pytest.approx(
                [shown[name] for name in CONDITION_METRICS], rel=1e-12)
    assert result.worst_condition == NAMES[int(np.argmax(result.condition_f))]
    # The answer checked at the tighter solver tolerance in every condition (in the
    # coordinator's process): the same bits as the check run here.
    from suspension_tuning.answer_check import check_condition_options

    runs = check_condition_options('ride', 2)['check_model'](
        np.asarray(result.x)[None, :], conditions.conditions)
    largest = max(0.0, max(float(np.max(run.g)) for run in runs))
    assert result.check_max_violation == largest
    assert result.check == ('feasible' if largest <= 5e-3 else 'infeasible')  # vehicle.yaml
    assert 'at the tighter tolerance' in result.check_note
    assert 'largest g at the check in condition' in result.check_note
    assert result.f == pytest.approx(max(result.condition_f))  # the worst-case objective
    assert result.baseline_f == pytest.approx(max(result.condition_baseline_f))
    report = format_result(result)  # what tune prints: every condition, the worst named
    assert f'worst: {result.worst_condition}' in report
    assert all(f'condition {name}: f ' in report for name in NAMES)
    # The bag: the condition set in the run configuration, the per-condition result.
    recorder = next(n for n in nodes if isinstance(n, RecorderNode))
    deadline = time.monotonic() + 30.0
    while not recorder.session.closed_bags and time.monotonic() < deadline:
        time.sleep(0.05)
    contents = read_messages(recorder.session.closed_bags[0])
    config = yaml.safe_load(contents.metadata['run_config']['yaml'])
    assert [c['name'] for c in config['conditions']['conditions']] == NAMES
    assert config['condition_form'] == 'worst'
    recorded = decode(contents, contents.on('/optimisation/result')[0])
    assert list(recorded.condition_metrics) == list(result.condition_metrics)
    assert recorded.worst_condition == result.worst_condition
    # inspect_bag reads them back per condition
    bag = recorder.session.closed_bags[0]
    table = summary(bag)['optimum']['conditions']
    assert table['worst'] == result.worst_condition
    assert table['per_condition'][NAMES[1]]['physical_metrics']['reported'] == dict(
        zip(CONDITION_METRICS, result.condition_metrics[k:2 * k]))
    assert f'condition {NAMES[2]}: f baseline' in _format(summary(bag))
    plots = write_plots(bag, tmp_path / 'plots')
    assert tmp_path / 'plots' / 'conditions.png' in plots


def test_a_bad_condition_set_is_a_bad_goal(graph):
    from suspension_tuning_interfaces.action import Optimise

    _, client_node = graph
    result = _run(client_node, Optimise.Goal(
        scenario='ride', n_vars=2, gradient_source='simplified',
        conditions='{"conditions": [{"name": "heavy", "speed_kmh": 50.0, '
                   '"payload": {"mass_kg": 2000.0, "behind_front_axle_m": 2.0}}]}'))
    assert not result.success
    assert "condition 'heavy': payload.mass_kg: 2000 kg is outside 0-650 kg" in result.message


def test_a_constraint_on_a_ride_metric_holds_in_every_condition_of_a_goal(graph):
    from suspension_tuning_interfaces.action import Optimise
    from suspension_tuning_interfaces.msg import Constraint

    from suspension_tuning import evaluation
    from suspension_tuning.conditions import ConditionSet, load_conditions

    _, client_node = graph
    names = NAMES[:2]
    shipped = load_conditions()
    conditions = ConditionSet(tuple(c for name in names for c in shipped.conditions
                                    if c.name == name), 'test')
    # the driver's seat W_b RMS at most 1.0 m/s^2 (the baseline's is 1.12 unladen at
    # 50 km/h, README), in both conditions
    result = _run(client_node, Optimise.Goal(
        scenario='ride', n_vars=2, gradient_source='simplified', max_iterations=2,
        conditions=conditions.as_text(), condition_form='worst',
        constraints=[Constraint(scenario='ride', quantity='a_rms_driver_mps2',
                                upper_bound=1.0)]))
    assert len(result.x) == 2, result.message
    assert list(result.constraint_gradient_sources) == ['full']  # a metric: central diff.
    # The reported design's metric in each condition, in-process: the worst is reported,
    # and g holds one row per condition after the 4 tyre-hop rows of each.
    runs = [evaluation.evaluate('ride', np.asarray(result.x)[None, :], condition=c.as_text())
            for c in conditions.conditions]
    values = [float(run.metrics[0][list(run.metric_names).index('a_rms_driver_mps2')])
              for run in runs]
    assert list(result.constraint_values) == pytest.approx([max(values)], rel=1e-12)
    assert list(result.g[-2:]) == pytest.approx([v - 1.0 for v in values], rel=1e-12)
    assert len(result.g) == 4 * 2 + 2
    # feasible means every row within the ride's gtol (config/optimiser.yaml, 1e-3)
    assert result.feasible == (max(result.g) <= 1e-3)


def test_a_handling_goal_over_two_conditions_reports_each_at_its_manoeuvre_speed(graph):
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning import evaluation
    from suspension_tuning.conditions import ConditionSet, load_conditions
    from suspension_tuning.nodes._conditions import CONDITION_METRICS
    from suspension_tuning.paths import config_dir
    from suspension_tuning.physical_metrics import physical_metrics

    _, client_node = graph
    shipped = load_conditions(config_dir() / 'conditions_handling.yaml')
    conditions = ConditionSet(tuple(c for c in shipped.conditions
                                    if c.name in ('unladen_50', 'laden_65')), 'test')
    result = _run(client_node, Optimise.Goal(
        scenario='handling', n_vars=2, gradient_source='simplified', max_iterations=2,
        conditions=conditions.as_text(), condition_form='worst'))
    assert len(result.x) == 2, result.message
    assert result.n_calibration_runs == 2 * SAMPLES  # each condition calibrated in it
    shown = CONDITION_METRICS['handling']
    assert list(result.condition_metric_names) == shown
    k = len(shown)
    # each condition's lane change at its own speed with its payload, in-process: the
    # same bits as the workers' runs
    for c, condition in enumerate(conditions.conditions):
        run = evaluation.evaluate('handling', np.asarray(result.x)[None, :],
                                  condition=condition.as_text())
        assert result.condition_f[c] == run.f[0]
        metrics = physical_metrics('handling', run.metric_names, run.metrics[0])
        assert list(result.condition_metrics[c * k:(c + 1) * k]) == pytest.approx(
            [metrics[name] for name in shown], rel=1e-12)
    assert result.worst_condition == 'laden_65'  # more roll, laden and faster
