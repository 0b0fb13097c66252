"""Simulation node and coordinator on real executors (full-model gradients).

The graph must give the same bits as the in-process loop: the same designs are
simulated by the same deterministic model, only the transport differs.
"""

import re

import numpy as np
import pytest

from suspension_tuning.testing import wait_for_future as wait

pytestmark = pytest.mark.ros


def call(client, request, timeout_s=120.0):
    assert client.wait_for_service(timeout_sec=10.0)
    return wait(client.call_async(request), timeout_s)


def test_sim_service_matches_in_process_and_survives_bad_requests(ros_context, executor):
    from rclpy.node import Node
    from suspension_tuning_interfaces.srv import EvaluateDesign

    from suspension_tuning import evaluation
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode

    sim = FullVehicleSimNode(context=ros_context)
    client_node = Node('sim_test_client', context=ros_context)
    executor.add(sim, client_node)
    client = client_node.create_client(EvaluateDesign, '/full_vehicle_sim/evaluate')
    designs = np.array([[0.5005, 0.5005], [0.2, 0.9]])
    response = call(client, EvaluateDesign.Request(scenario='ride', n_vars=2,
                                                   designs=designs.ravel().tolist()))
    assert response.success, response.error
    local = evaluation.evaluate('ride', designs)
    np.testing.assert_array_equal(response.f, local.f)  # same bits through the graph
    np.testing.assert_array_equal(np.reshape(response.g, (2, 4)), local.g)
    assert response.n_constraints == 4  # eq. 11: one per tyre
    assert len(response.metrics) == 2 * len(response.metric_names)
    bad = [
        (dict(scenario='offroad', n_vars=2, designs=[0.5, 0.5]), 'unknown scenario'),
        (dict(scenario='ride', n_vars=2, designs=[0.5, 0.5, 0.5]), 'multiple'),
        (dict(scenario='ride', n_vars=3, designs=[0.5, 0.5, 0.5]), 'n_vars'),
        (dict(scenario='ride', n_vars=2, designs=[0.5, float('nan')]), 'NaN|nan|finite'),
        (dict(scenario='ride', n_vars=2, designs=[0.5, 1.2]), 'bound|range|outside'),
    ]
    for fields, message in bad:
        answer = call(client, EvaluateDesign.Request(**fields))
        assert not answer.success
        assert answer.error
        assert re.search(message, answer.error), answer.error
    again = call(client, EvaluateDesign.Request(scenario='ride', n_vars=2,
                                                designs=[0.5005, 0.5005]))
    assert again.success and again.f[0] == response.f[0]  # still serving, same bits


def test_a_request_of_more_designs_than_the_worker_takes_is_refused_at_once(
        ros_context, executor):
    """5,000 designs (minutes of work) are refused without a run, naming the limit and
    its parameter; a lower limit set at run time applies to the next request."""
    import time

    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from suspension_tuning_interfaces.srv import EvaluateDesign

    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode

    sim = FullVehicleSimNode('limited_sim', context=ros_context)
    client_node = Node('limited_sim_client', context=ros_context)
    executor.add(sim, client_node)
    client = client_node.create_client(EvaluateDesign, '/limited_sim/evaluate')
    start = time.monotonic()
    answer = call(client, EvaluateDesign.Request(scenario='ride', n_vars=2,
                                                 designs=[0.5] * 2 * 5000))
    assert time.monotonic() - start < 10.0  # refused, not run (5,000 runs: ~4 min)
    assert not answer.success
    assert ('5000 designs in one request, more than this worker takes (parameter '
            'max_designs_per_request = 128)') in answer.error, answer.error
    assert sim.runs == 0
    [result] = sim.set_parameters([Parameter('max_designs_per_request', value=2)])
    assert result.successful, result.reason
    three = call(client, EvaluateDesign.Request(scenario='ride', n_vars=2, designs=[0.5] * 6))
    assert not three.success and 'max_designs_per_request = 2' in three.error
    two = call(client, EvaluateDesign.Request(scenario='ride', n_vars=2, designs=[0.5] * 4))
    assert two.success and len(two.f) == 2 and sim.runs == 2, two.error


def test_coordinator_action_with_full_gradients_equals_in_process(ros_context, executor):
    from rclpy.action import ActionClient
    from rclpy.node import Node
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning import evaluation
    from suspension_tuning.answer_check import check_options
    from suspension_tuning.nodes.coordinator import CoordinatorNode
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode
    from suspension_tuning.tuning import (
        FullEvaluation,
        TuningRequest,
        optimise,
        with_noise_levels,
    )

    sim = FullVehicleSimNode(context=ros_context)
    coordinator = CoordinatorNode(context=ros_context)
    client_node = Node('coordinator_test_client', context=ros_context)
    executor.add(sim, coordinator, client_node)
    client = ActionClient(client_node, Optimise, '/coordinator/optimise')
    assert client.wait_for_server(timeout_sec=10.0)
    feedback = []
    goal = Optimise.Goal(scenario='handling', n_vars=2, gradient_source='full',
                         max_iterations=4)
    handle = wait(client.send_goal_async(goal, feedback_callback=feedback.append))
    assert handle.accepted
    result = wait(handle.get_result_async(), 300.0).result
    assert result.iterations >= 1
    assert len(feedback) == len(result.history)
    # In-process run of the same loop: identical iterates and counts.
    options = coordinator.options.as_dict() | {'maxiter': 4}

    def full_model(points):
        run = evaluation.evaluate('handling', points)
        return FullEvaluation(run.f, run.g)

    # the built-in model: the coordinator's noise levels and the check of the answer
    local = optimise(TuningRequest('handling', 2, None, 'full',
                                   with_noise_levels(options, 'handling')), full_model,
                     **check_options('handling', 2))
    np.testing.assert_array_equal(result.x, local.x_best)  # the reported (best) design
    assert result.f == local.f_best and result.best_iteration == local.best_iteration
    assert result.n_full_runs == local.n_full_runs
    # Per iteration: one full run (a design evaluated before is not run again), plus
    # 2n = 4 for each central-difference gradient, and the check of the answer at the
    # tighter tolerance (feasible: no continuation).
    assert result.check == 'feasible' and not local.check['continued']
    distinct = len({tuple(np.asarray(r['x'], float)) for r in local.history})
    assert result.n_full_runs == distinct + 4 * local.ngev + 1
    assert result.physical_names[0] == 'dpsf_front'

    bad = wait(client.send_goal_async(Optimise.Goal(scenario='ride', n_vars=5)))
    bad_result = wait(bad.get_result_async()).result
    assert not bad_result.success and 'n_vars' in bad_result.message


def test_a_destroyed_coordinator_leaves_no_action_server_behind(ros_context, ros_domain_id):
    """rclpy's Node.destroy_node leaves action servers alone; a stale ``optimise``
    server would take the goals of a later ``tune`` and never answer them."""
    from contextlib import ExitStack

    import rclpy
    from rclpy.action import get_action_names_and_types

    from suspension_tuning.nodes.coordinator import CoordinatorNode
    from suspension_tuning.testing import isolated_context, wait_until

    cleanup = ExitStack()
    other = cleanup.enter_context(isolated_context(ros_domain_id))  # a second process, as it were
    watcher = rclpy.create_node('watcher', context=other)

    # A namespace of its own: a coordinator left by another test or process on this
    # domain must not count.
    def seen() -> bool:
        return any(name == '/destroy_test/coordinator/optimise'
                   for name, _ in get_action_names_and_types(watcher))

    try:
        coordinator = CoordinatorNode(context=ros_context, namespace='/destroy_test')
        assert wait_until(seen), 'the coordinator never appeared'
        coordinator.destroy_node()
        assert wait_until(lambda: not seen()), 'the destroyed coordinator is still seen'
    finally:
        watcher.destroy_node()
        cleanup.close()
