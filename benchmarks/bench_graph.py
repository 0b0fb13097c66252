"""ROS overhead of the tuning graph: the same optimisation through the graph and in-process.

Runs the 2-variable ride optimisation with simplified-model gradients (eq. 25
calibration from 30 full-model samples included) twice:

- in-process: ``tuning.optimise`` calling the physics directly;
- through the graph: simulation worker, gradient evaluator and coordinator nodes on
  one MultiThreadedExecutor, the goal sent by an action client (calibration over the
  graph too, from an empty cache).

Prints ``name: value`` lines, ending with ``ros_overhead_fraction`` = graph wall time /
in-process wall time - 1 (target <= 0.02).  Both runs must reach the same bits.
DDS stays on loopback with a domain of its own.
"""

from __future__ import annotations

import os
import sys
import tempfile
import threading
import time

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', '91')

import numpy as np  # noqa: E402

SCENARIO, N_VARS, SAMPLES, REPEATS = 'ride', 2, 30, 3


def in_process(options: dict) -> tuple[float, object]:
    from suspension_tuning import evaluation
    from suspension_tuning.optim.simplified_gradient import SimplifiedGradient, calibrate
    from suspension_tuning.tuning import FullEvaluation, RunCounter, TuningRequest, optimise

    start = time.perf_counter()
    scaling = calibrate(SCENARIO, N_VARS, n_samples=SAMPLES)

    def full_model(points):
        run = evaluation.evaluate(SCENARIO, points)
        return FullEvaluation(run.f, run.g, run.result)

    result = optimise(TuningRequest(SCENARIO, N_VARS, None, 'simplified', options), full_model,
                      SimplifiedGradient(SCENARIO, N_VARS, scaling),
                      counter=RunCounter(calibration_runs=SAMPLES))
    return time.perf_counter() - start, result


def through_graph() -> tuple[float, object, dict]:
    import rclpy
    from rclpy.action import ActionClient
    from rclpy.executors import MultiThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.nodes.coordinator import CoordinatorNode
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode
    from suspension_tuning.nodes.gradient_evaluator import GradientEvaluatorNode

    rclpy.init()
    with tempfile.TemporaryDirectory() as cache:
        nodes = [FullVehicleSimNode(),
                 GradientEvaluatorNode(parameter_overrides=[
                     Parameter('calibration_dir', value=cache)]),
                 CoordinatorNode(parameter_overrides=[
                     Parameter('calibration_samples', value=SAMPLES),
                     Parameter('final_telemetry', value=False)])]
        client_node = Node('bench_graph_client')
        executor = MultiThreadedExecutor(num_threads=8)
        for node in [*nodes, client_node]:
            executor.add_node(node)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
        client = ActionClient(client_node, Optimise, '/coordinator/optimise')
        client.wait_for_server(timeout_sec=30.0)
        options = nodes[2].options.as_dict()
        done = threading.Event()
        start = time.perf_counter()
        goal = client.send_goal_async(Optimise.Goal(scenario=SCENARIO, n_vars=N_VARS,
                                                    gradient_source='simplified'))
        goal.add_done_callback(lambda _: done.set())
        done.wait()
        done.clear()
        outcome = goal.result().get_result_async()
        outcome.add_done_callback(lambda _: done.set())
        done.wait()
        elapsed = time.perf_counter() - start
        result = outcome.result().result
        executor.shutdown()
        spinner.join(timeout=10)
        for node in [*nodes, client_node]:
            node.destroy_node()
    rclpy.shutdown()
    return elapsed, result, options


def main() -> int:
    from suspension_tuning import evaluation

    evaluation.evaluate(SCENARIO, np.full((1, N_VARS), 0.5))  # compile / load the kernels
    graph_times, local_times = [], []
    for _ in range(REPEATS):
        graph_s, graph_result, options = through_graph()
        local_s, local_result = in_process(options)
        graph_times.append(graph_s)
        local_times.append(local_s)
    same = bool(np.array_equal(graph_result.x, local_result.x)
                and graph_result.f == local_result.f)
    graph_s, local_s = min(graph_times), min(local_times)
    print(f'iterations: {graph_result.iterations}')
    print(f'full_runs: {graph_result.n_full_runs}')
    print(f'simplified_runs: {graph_result.n_simplified_runs}')
    print(f'calibration_runs: {graph_result.n_calibration_runs}')
    print(f'same_result_bits: {same}')
    print(f'in_process_wall_s: {local_s:.3f}')
    print(f'graph_wall_s: {graph_s:.3f}')
    print(f'repeats_best_of: {REPEATS}')
    # Round trips: one evaluate per iteration (n_full_runs), one gradient call per 2n
    # simplified runs, the calibration call and its batch of full-model samples.
    trips = (graph_result.n_full_runs + graph_result.n_simplified_runs // (2 * N_VARS) + 2)
    print(f'service_round_trips: {trips}')
    print(f'overhead_per_round_trip_ms: {(graph_s - local_s) / trips * 1e3:.2f}')
    print(f'ros_overhead_fraction: {graph_s / local_s - 1.0:.4f}')
    return 0 if same else 1


if __name__ == '__main__':
    sys.exit(main())
