"""The whole graph in one process (``ros2 run suspension_tuning graph``, ``make demo``).

The nodes of ``graph.build_nodes``, each on the executor it asks for
(``graph.SpinningGraph``): a goal runs in the coordinator's execute callback and
waits there for the services of the other nodes, over the middleware as between
processes.  A 2-variable ride optimisation through it must reach the in-process
bits (the services count their calls), and a cancel must stop it, also of a goal
queued behind another.
"""

import threading

import numpy as np
import pytest
from rclpy.parameter import Parameter

pytestmark = pytest.mark.ros

SAMPLES = 12  # fewer than the paper's 30 to keep the test short; same code path
RESULT_TIMEOUT_S = 1.0  # results kept 1 s after their goal ends (config: 10 s)


@pytest.fixture
def one_process_graph(ros_context, tmp_path):
    """(nodes, coordinator, client node, goal threads, graph): spinning, no recorder."""
    from rclpy.node import Node

    from suspension_tuning.graph import SpinningGraph, build_nodes
    from suspension_tuning.nodes.coordinator import CoordinatorNode

    nodes = build_nodes(workers=1, record=False, context=ros_context, overrides={
        'gradient_evaluator': [Parameter('calibration_dir', value=str(tmp_path))],
        'coordinator': [Parameter('calibration_samples', value=SAMPLES),
                        Parameter('result_timeout_s', value=RESULT_TIMEOUT_S)]})
    coordinator = next(n for n in nodes if isinstance(n, CoordinatorNode))
    goal_threads: list[int] = []
    execute = coordinator._execute

    def recording_execute(goal_handle):
        goal_threads.append(threading.get_ident())
        return execute(goal_handle)

    coordinator.server.register_execute_callback(recording_execute)
    client_node = Node('one_process_client', context=ros_context)
    graph = SpinningGraph(nodes, [client_node])
    try:
        yield nodes, coordinator, client_node, goal_threads, graph
    finally:
        graph.shutdown()


def _send(client_node, goal, feedback_callback=None):
    from rclpy.action import ActionClient
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.nodes._spin import wait_future

    client = ActionClient(client_node, Optimise, '/coordinator/optimise')
    assert client.wait_for_server(timeout_sec=10.0)
    return wait_future(client.send_goal_async(goal, feedback_callback=feedback_callback),
                       30.0)


def test_ride_optimisation_through_the_one_process_graph_gives_the_in_process_bits(
        one_process_graph, in_process_optimum):
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.nodes._spin import wait_future

    nodes, coordinator, client_node, goal_threads, graph = one_process_graph
    feedback = []
    handle = _send(client_node, Optimise.Goal(scenario='ride', n_vars=2,
                                              gradient_source='simplified'),
                   feedback.append)
    result = wait_future(handle.get_result_async(), 300.0).result
    assert result.success, result.message
    # Not on the thread that spins the coordinator's executor (a thread of its pool).
    executor_thread = graph.threads[graph.nodes.index(coordinator)]
    assert len(goal_threads) == 1 and goal_threads[0] != executor_thread.ident
    # Every full run went over the middleware: the calibration batch (its 12 samples in
    # three pieces of 4: one worker, pieces_per_worker = 3, config/graph.yaml), one per iteration
    # evaluated, the baseline design's run (its physical metrics in the result) and the
    # telemetry run of the optimum (final_telemetry).  A continuation on the check's
    # model (where the check refuses the answer: at this answer its largest g sits within
    # one lift-off sample of the tolerance, so the machine's libm decides) runs in the
    # coordinator, not over the middleware: its records are not the workers'.
    local = in_process_optimum(coordinator.options.as_dict(), SAMPLES)
    over_middleware = (local.check['first_iteration'] if local.check['continued']
                       else len(result.history))
    assert nodes[0].evaluate_calls == 3 + over_middleware + 1 + 1
    assert len(result.baseline_metrics) == len(result.metrics) == len(result.metric_names)
    assert [m.feedback.phase for m in feedback].count('iteration') == len(result.history)
    assert result.n_calibration_runs == SAMPLES
    # The result reports the in-process run's best iterate, by its iteration in the
    # history; the last iterate stays the history's last record.
    np.testing.assert_array_equal(result.x, local.x_best)
    assert result.f == local.f_best
    assert (result.best_iteration, result.feasible, result.max_violation) == (
        local.best_iteration, local.best_feasible, local.max_violation_best)
    best = result.history[result.best_iteration]
    assert list(best.x) == list(result.x) and best.f == result.f
    np.testing.assert_array_equal(result.history[-1].x, local.x)
    assert result.message.startswith(
        f'best feasible design: iteration {result.best_iteration}; Dynamic-Q ')


def test_handling_optimisation_passes_the_full_runs_inputs_to_the_gradient(
        one_process_graph, in_process_optimum):
    """Paper 6.1: the simplified handling model runs on the full run's steering and
    slip angles at x.  They travel in the evaluate response and the gradient request
    (``simplified_inputs.pack``/``unpack``); the graph must reach the in-process bits,
    where the inputs are handed over as arrays."""
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.nodes._spin import wait_future

    _, coordinator, client_node, _, _ = one_process_graph
    handle = _send(client_node, Optimise.Goal(scenario='handling', n_vars=2,
                                              gradient_source='simplified'))
    result = wait_future(handle.get_result_async(), 300.0).result
    assert result.success, result.message
    assert result.n_calibration_runs == SAMPLES

    local = in_process_optimum(coordinator.options.as_dict(), SAMPLES, 'handling')
    assert result.iterations == local.nit
    assert result.n_simplified_runs == local.n_simplified_runs
    np.testing.assert_array_equal(result.x, local.x_best)  # the reported (best) design
    assert result.f == local.f_best and result.best_iteration == local.best_iteration


def test_a_goal_is_cancelled_between_iterations(one_process_graph):
    from action_msgs.msg import GoalStatus
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.nodes._spin import wait_future

    _, coordinator, client_node, goal_threads, graph = one_process_graph
    first = threading.Event()
    # Full-model gradients: 2n + 1 = 5 full runs per iteration, so that the cancel
    # (sent at the first feedback) lands while the optimisation still runs.
    handle = _send(client_node, Optimise.Goal(scenario='ride', n_vars=2,
                                              gradient_source='full', max_iterations=20),
                   lambda _: first.set())
    assert first.wait(120.0), 'no feedback'
    cancel = wait_future(handle.cancel_goal_async(), 30.0)
    # Accepted by another thread of the coordinator's executor while the goal runs.
    assert len(cancel.goals_canceling) == 1
    answer = wait_future(handle.get_result_async(), 300.0)
    assert answer.status == GoalStatus.STATUS_CANCELED
    # cancelled, and the best design of the iterations run so far reported
    assert answer.result.message.startswith('cancelled; best feasible design: iteration ')
    # Stopped at the iteration after the cancel, not after 20.
    assert 1 <= len(answer.result.history) <= 3
    # Never on the coordinator's executor.
    executor_thread = graph.threads[graph.nodes.index(coordinator)]
    assert len(goal_threads) == 1 and goal_threads[0] != executor_thread.ident


def test_a_result_asked_for_after_the_goal_ended_still_comes(one_process_graph):
    """A bad goal ends at once (aborted, with the reason); its result asked later."""
    import time

    from action_msgs.msg import GoalStatus
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.nodes._spin import wait_future

    _, _, client_node, goal_threads, _ = one_process_graph
    handle = _send(client_node, Optimise.Goal(scenario='bumpy', n_vars=2))
    deadline = time.monotonic() + 30.0
    while not goal_threads and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.2)  # the goal has ended before its result is asked for
    answer = wait_future(handle.get_result_async(), 30.0)
    assert answer.status == GoalStatus.STATUS_ABORTED
    assert not answer.result.success
    assert "unknown scenario 'bumpy'" in answer.result.message


def test_a_result_is_forgotten_result_timeout_after_its_goal_ended(one_process_graph):
    """rcl expires an ended goal after ``result_timeout_s`` (its timer is waited on by
    the coordinator's executor): a result
    asked for later is UNKNOWN, and the goal no longer appears in the status."""
    import time

    from action_msgs.msg import GoalStatus
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.nodes._spin import wait_future

    _, coordinator, client_node, _, _ = one_process_graph
    handle = _send(client_node, Optimise.Goal(scenario='bumpy', n_vars=2))
    assert wait_future(handle.get_result_async(), 30.0).status == GoalStatus.STATUS_ABORTED
    ended = time.monotonic()
    deadline = ended + 30.0
    while coordinator.server._goal_handles and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not coordinator.server._goal_handles, 'the ended goal was never expired'
    assert time.monotonic() - ended >= RESULT_TIMEOUT_S - 0.1  # not before its time
    late = wait_future(handle.get_result_async(), 30.0)
    assert late.status == GoalStatus.STATUS_UNKNOWN


def test_a_goal_cancelled_while_queued_behind_another_never_runs(one_process_graph):
    """Goals run one after another; one cancelled while it waits
    ends at its start, without a model run, and the running goal is not disturbed."""
    from action_msgs.msg import GoalStatus
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.nodes._spin import wait_future

    _, _, client_node, goal_threads, _ = one_process_graph
    first = threading.Event()
    # Full-model gradients (5 full runs per iteration): the first goal still runs
    # for about a second after its first feedback.
    goal = Optimise.Goal(scenario='ride', n_vars=2, gradient_source='full', max_iterations=20)
    running = _send(client_node, goal, lambda _: first.set())
    assert first.wait(120.0), 'no feedback'
    queued = _send(client_node, goal)  # accepted while the first goal waits for a service
    cancel = wait_future(queued.cancel_goal_async(), 30.0)
    assert len(cancel.goals_canceling) == 1
    late = wait_future(queued.get_result_async(), 300.0)
    done = wait_future(running.get_result_async(), 300.0)
    assert done.status == GoalStatus.STATUS_SUCCEEDED and done.result.success
    assert late.status == GoalStatus.STATUS_CANCELED
    assert late.result.message == 'cancelled before it started'
    assert late.result.n_full_runs == 0 and len(late.result.history) == 0
    assert len(goal_threads) == 2  # both went through the execute callback, in order


def test_a_node_of_ones_own_takes_the_place_of_the_graphs(ros_context):
    """``build_nodes(factories=...)``: the graph's parameters and overrides reach it;
    a factory for a node the graph does not have is an error."""
    from rclpy.node import Node

    from suspension_tuning.graph import build_nodes
    from suspension_tuning.nodes.valve_controller import ValveControllerNode

    class OwnController(Node):
        def __init__(self, **kwargs):
            super().__init__('valve_controller', **kwargs)
            self.declare_parameter('gain', 0.0)

    nodes = build_nodes(record=False, context=ros_context,
                        overrides={'valve_controller': [Parameter('gain', value=2.5)]},
                        factories={'valve_controller': OwnController})
    try:
        [own] = [node for node in nodes if node.get_name() == 'valve_controller']
        assert isinstance(own, OwnController)
        assert not any(isinstance(node, ValveControllerNode) for node in nodes)
        assert own.get_parameter('gain').value == 2.5
        assert [node.get_name() for node in nodes] == [
            'full_vehicle_sim', 'gradient_evaluator', 'valve_controller', 'coordinator']
    finally:
        for node in nodes:
            node.destroy_node()
    with pytest.raises(ValueError, match='no node valve_controler in the graph'):
        build_nodes(record=False, context=ros_context,
                    factories={'valve_controler': OwnController})  # misspelt: not added
