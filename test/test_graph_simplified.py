"""Gradient evaluator and the coordinator with simplified-model gradients (eq. 25).

A 2-variable ride optimisation runs end to end through the graph: calibration from
full-model samples fetched over the graph, Dynamic-Q with one full run and 2n
simplified runs per iteration.  The same loop in-process gives the same bits.
"""

import re

import numpy as np
import pytest
from rclpy.parameter import Parameter

from suspension_tuning.testing import wait_for_future as wait

pytestmark = pytest.mark.ros

SAMPLES = 12  # fewer than the paper's 30 to keep the test short; same code path


@pytest.fixture
def graph(ros_context, executor, tmp_path):
    from rclpy.node import Node

    from suspension_tuning.nodes.coordinator import CoordinatorNode
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode
    from suspension_tuning.nodes.gradient_evaluator import GradientEvaluatorNode

    sim = FullVehicleSimNode(context=ros_context)
    gradient = GradientEvaluatorNode(context=ros_context, parameter_overrides=[
        Parameter('calibration_dir', value=str(tmp_path))])
    coordinator = CoordinatorNode(context=ros_context, parameter_overrides=[
        Parameter('calibration_samples', value=SAMPLES)])
    client = Node('graph_test_client', context=ros_context)
    executor.add(sim, gradient, coordinator, client)
    return {'sim': sim, 'gradient': gradient, 'coordinator': coordinator, 'client': client}


def test_ride_optimisation_with_simplified_gradients_converges_through_the_graph(
        graph, in_process_optimum):
    from rclpy.action import ActionClient
    from suspension_tuning_interfaces.action import Optimise

    client = ActionClient(graph['client'], Optimise, '/coordinator/optimise')
    assert client.wait_for_server(timeout_sec=10.0)
    feedback = []
    handle = wait(client.send_goal_async(
        Optimise.Goal(scenario='ride', n_vars=2, gradient_source='simplified'),
        feedback_callback=feedback.append))
    result = wait(handle.get_result_async()).result
    assert result.success, result.message
    assert result.n_calibration_runs == SAMPLES
    n = 2
    # Paper section 2: one full run per iteration (per evaluation) and 2n simplified
    # runs per gradient, plus one at the iterate for the correction's values; no
    # full-model gradient runs.
    # and the check of the answer at the tighter tolerance, paid too.  At this answer
    # the check's largest g sits within one lift-off sample (0.00074) of its tolerance
    # 0.005, so the machine's libm decides whether it refuses it; a refused answer goes
    # on on the check model, whose first record is the check's run (no extra run).
    local = in_process_optimum(graph['coordinator'].options.as_dict(), SAMPLES)
    iterations_evaluated = len(result.history)
    assert result.check == 'feasible'
    assert result.n_full_runs == iterations_evaluated + (0 if local.check['continued'] else 1)
    assert result.n_simplified_runs % (2 * n + 1) == 0 and result.n_simplified_runs > 0
    phases = [message.feedback.phase for message in feedback]
    assert phases.count('iteration') == len(result.history)
    # The calibration's progress comes first, a step per piece of the batch (one worker:
    # pieces_per_worker = 3 pieces of 4 designs, config/graph.yaml) of the 12 samples.
    calibration = [(m.feedback.calibration.samples_done, m.feedback.calibration.samples_total)
                   for m in feedback if m.feedback.phase == 'calibration']
    assert calibration == [(4, SAMPLES), (8, SAMPLES), (SAMPLES, SAMPLES)]
    assert phases[:3] == ['calibration'] * 3
    # The same loop in-process, with the in-process eq. 25 calibration: same bits.
    np.testing.assert_array_equal(result.x, local.x_best)  # the reported (best) design
    assert result.f == local.f_best and result.best_iteration == local.best_iteration
    assert result.n_simplified_runs == local.n_simplified_runs


def test_a_ride_goal_by_default_spends_no_calibration_and_pays_what_the_benchmark_counts(
        graph):
    from rclpy.action import ActionClient
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.optim.simplified_gradient import SimplifiedGradient
    from suspension_tuning.studies import common
    from suspension_tuning.studies import method_benchmark as mb
    from suspension_tuning.tune import format_result, paid_full_runs

    # -1: each case's default, config/simplified_models.yaml scaling.run_samples
    # (ride, 2 variables: none, unit scaling corrected along the run)
    graph['coordinator'].set_parameters([Parameter('calibration_samples', value=-1)])
    client = ActionClient(graph['client'], Optimise, '/coordinator/optimise')
    assert client.wait_for_server(timeout_sec=10.0)
    feedback = []
    handle = wait(client.send_goal_async(
        Optimise.Goal(scenario='ride', n_vars=2, gradient_source='simplified'),
        feedback_callback=feedback.append))
    result = wait(handle.get_result_async()).result
    assert result.success, result.message
    assert result.n_calibration_runs == 0
    phases = [m.feedback.phase for m in feedback]
    assert 'calibration' not in phases  # no samples, so no sample progress
    [note] = [m.feedback.note for m in feedback if m.feedback.phase == 'calibration_fit']
    assert 'no eq. 25 calibration (0 full-model samples' in note
    # The benchmark's run of ours from the same start (the goal's default: the centre)
    samples = mb.bench_calibration_samples('ride', 2)
    assert samples == 0
    run = mb.run_method('dq_simplified', 'ride', 2, 'centre', common.start_point('centre', 2),
                        mb.REFERENCE_INTEGRATOR,
                        SimplifiedGradient('ride', 2, None, common.FD_STEP),
                        calibration_samples=samples)
    np.testing.assert_array_equal(result.x, run.x)
    assert paid_full_runs(result) == run.n_full_runs + run.n_calibration_runs
    assert f'paid full-model runs: {paid_full_runs(result)} ' in format_result(result)


def test_gradient_service_errors_and_calibration_cache(graph, monkeypatch):
    from suspension_tuning_interfaces.srv import Calibrate, EvaluateGradient

    from suspension_tuning.nodes import gradient_evaluator

    node = graph['client']
    gradient = node.create_client(EvaluateGradient, '/gradient_evaluator/gradient')
    calibrate = node.create_client(Calibrate, '/gradient_evaluator/calibrate')
    assert gradient.wait_for_service(timeout_sec=10.0)
    uncalibrated = wait(gradient.call_async(EvaluateGradient.Request(
        scenario='ride', n_vars=2, x=[0.5, 0.5])))
    assert not uncalibrated.success and 'calibrat' in uncalibrated.error
    first = wait(calibrate.call_async(Calibrate.Request(scenario='ride', n_vars=2,
                                                        n_samples=SAMPLES)))
    assert first.success and not first.from_cache and first.n_full_runs == SAMPLES
    assert first.function_names[0] == 'f'

    def no_sampling(*args, **kwargs):
        raise AssertionError('a cached calibration sampled its designs')

    # Served from the cache: the key needs no designs (their maximin LHS takes ~7 ms).
    monkeypatch.setattr(gradient_evaluator, 'calibration_designs', no_sampling)
    second = wait(calibrate.call_async(Calibrate.Request(scenario='ride', n_vars=2,
                                                         n_samples=SAMPLES)))
    assert second.success and second.from_cache and second.n_full_runs == 0
    np.testing.assert_array_equal(second.r_squared, first.r_squared)  # NaN: constant g
    for fields, message in [
        (dict(scenario='ride', n_vars=2, x=[0.5, float('nan')]), 'NaN|nan|finite'),
        (dict(scenario='ride', n_vars=2, x=[0.5]), 'length|shape|expected'),
        (dict(scenario='ride', n_vars=2, x=[0.5, 1.5]), 'bound|range|outside'),
        (dict(scenario='rally', n_vars=2, x=[0.5, 0.5]), 'unknown scenario'),
        (dict(scenario='handling', n_vars=2, x=[0.5, 0.5]), 'calibrat|inputs'),
    ]:
        answer = wait(gradient.call_async(EvaluateGradient.Request(**fields)))
        assert not answer.success
        assert re.search(message, answer.error), answer.error
    good = wait(gradient.call_async(EvaluateGradient.Request(scenario='ride', n_vars=2,
                                                             x=[0.5, 0.5])))
    # 2n stencil runs and x itself; the values at x are eq. 25 of the model's values
    assert good.success and len(good.df) == 2 and good.n_model_runs == 5
    assert len(good.values) == 1 + good.n_constraints


def test_an_eight_variable_goal_reports_every_variable_by_name_and_unit_and_moves_the_bar(
        graph):
    # the ride8 preset of config/design_space.yaml on the handling scenario: compression,
    # rebound and gas volume per axle and both anti-roll bars.  The full model says a
    # stiffer rear bar lowers f_hand (eq. 10) at the baseline (15 -> 40 kN m/rad: f 1.14
    # -> 0.84, docs/design_space.md), and the handling model sees the design's bars
    from rclpy.action import ActionClient
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.tune import format_feedback
    from suspension_tuning.vehicle.design import load_design_space

    space = load_design_space()
    x0 = space.baseline_x(8)
    client = ActionClient(graph['client'], Optimise, '/coordinator/optimise')
    assert client.wait_for_server(timeout_sec=10.0)
    feedback = []
    handle = wait(client.send_goal_async(
        Optimise.Goal(scenario='handling', n_vars=8, x0=x0.tolist(),
                      gradient_source='simplified', max_iterations=3),
        feedback_callback=feedback.append))
    result = wait(handle.get_result_async()).result
    names = space.names(8)
    assert list(result.physical_names) == list(names)
    assert len(names) == 8 and 'anti_roll_bar_rear_knm_per_rad' in names
    assert list(result.physical_units) == ['-', '-', 'L', '-', '-', 'L', 'kN.m/rad',
                                           'kN.m/rad']
    assert len(result.x) == 8 and len(result.baseline_physical_values) == 8
    values = dict(zip(result.physical_names, result.physical_values))
    baseline = dict(zip(result.physical_names, result.baseline_physical_values))
    assert baseline['anti_roll_bar_rear_knm_per_rad'] == pytest.approx(15.0)  # vehicle.yaml
    assert values['anti_roll_bar_rear_knm_per_rad'] > baseline['anti_roll_bar_rear_knm_per_rad']
    assert result.f < result.baseline_f
    lines = [format_feedback(m.feedback) for m in feedback if m.feedback.phase == 'iteration']
    assert lines and all('anti_roll_bar_front_knm_per_rad=' in line for line in lines)
