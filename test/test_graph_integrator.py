"""The full-model integrator through the graph: a service field, a node parameter and the
Optimise goal field; the graph gives the same bits as the in-process model."""

import numpy as np
import pytest

from suspension_tuning.testing import wait_for_future as wait

pytestmark = pytest.mark.ros


def call(client, request, timeout_s=120.0):
    assert client.wait_for_service(timeout_sec=10.0)
    return wait(client.call_async(request), timeout_s)


def test_sim_node_integrator_from_request_or_parameter(ros_context, executor):
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from suspension_tuning_interfaces.srv import EvaluateDesign

    from suspension_tuning import evaluation
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode

    sim = FullVehicleSimNode('integrator_sim', context=ros_context)
    client_node = Node('integrator_test_client', context=ros_context)
    executor.add(sim, client_node)
    client = client_node.create_client(EvaluateDesign, '/integrator_sim/evaluate')
    designs = [0.5005, 0.5005]
    local = evaluation.evaluate('ride', np.array([designs]), integrator='variable_step')
    by_field = call(client, EvaluateDesign.Request(scenario='ride', n_vars=2, designs=designs,
                                                   integrator='variable_step'))
    assert by_field.success, by_field.error
    assert by_field.f[0] == local.f[0]  # same bits through the graph
    default = call(client, EvaluateDesign.Request(scenario='ride', n_vars=2, designs=designs))
    assert default.f[0] == evaluation.evaluate('ride', np.array([designs])).f[0]
    # The parameter is read once at start-up (it names the model the worker announces):
    # set at run time it is refused, given at start-up it is the default of every request.
    refused = sim.set_parameters([Parameter('integrator', value='variable_step')])[0]
    assert not refused.successful and 'read-only' in refused.reason
    by_parameter_sim = FullVehicleSimNode(
        'integrator_sim_variable', context=ros_context,
        parameter_overrides=[Parameter('integrator', value='variable_step')])
    executor.add(by_parameter_sim)
    by_parameter_client = client_node.create_client(EvaluateDesign,
                                                    '/integrator_sim_variable/evaluate')
    by_parameter = call(by_parameter_client, EvaluateDesign.Request(scenario='ride', n_vars=2,
                                                                    designs=designs))
    assert by_parameter.f[0] == local.f[0]
    bad = call(client, EvaluateDesign.Request(scenario='ride', n_vars=2, designs=designs,
                                              integrator='euler'))
    assert not bad.success and 'unknown integrator' in bad.error


def test_optimise_goal_integrator_runs_the_variable_step_model(ros_context, executor):
    import yaml
    from rclpy.action import ActionClient
    from rclpy.node import Node
    from std_msgs.msg import String
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
    client_node = Node('integrator_goal_client', context=ros_context)
    configs = []
    client_node.create_subscription(String, '/optimisation/run_config',
                                    lambda m: configs.append(m.data), 1)
    executor.add(sim, coordinator, client_node)
    client = ActionClient(client_node, Optimise, '/coordinator/optimise')
    assert client.wait_for_server(timeout_sec=10.0)
    goal = Optimise.Goal(scenario='handling', n_vars=2, gradient_source='full',
                         max_iterations=2, integrator='variable_step')
    handle = wait(client.send_goal_async(goal))
    assert handle.accepted
    result = wait(handle.get_result_async(), 300.0).result
    assert result.iterations == 2  # stopped by max_iterations, as asked
    options = coordinator.options.as_dict() | {'maxiter': 2}

    def full_model(points):
        run = evaluation.evaluate('handling', points, integrator='variable_step')
        return FullEvaluation(run.f, run.g)

    local = optimise(TuningRequest('handling', 2, None, 'full',
                                   with_noise_levels(options, 'handling', 'variable_step')),
                     full_model, **check_options('handling', 2))
    np.testing.assert_array_equal(result.x, local.x_best)  # the reported (best) design
    assert result.f == local.f_best and result.best_iteration == local.best_iteration
    # the workers' default integrator is the fixed step: the variable-step goal's answer
    # is checked at the tighter tolerance all the same (no tyre lifts in the lane change)
    assert local.check['feasible_check'] and result.check == 'feasible'
    assert result.check_max_violation == local.check['max_violation_check']
    # the run configuration names the integrator
    assert configs and yaml.safe_load(configs[-1])['integrator'] == 'variable_step'
    bad = wait(client.send_goal_async(Optimise.Goal(scenario='ride', n_vars=2,
                                                    integrator='euler')))
    bad_result = wait(bad.get_result_async()).result
    assert not bad_result.success and 'unknown integrator' in bad_result.message
