"""``graph``: every node of the tuning graph in one process.

``ros2 run suspension_tuning graph --workers 2`` starts the simulation workers
(``sim_0``, ``sim_1``, ...), the gradient evaluator, the valve controller, the
coordinator and (unless ``--no-record``) the recorder, each node on an executor
of its own.
ROS parameters come from ``--ros-args --params-file config/graph.yaml`` like for any
node.  Each node also runs alone with ``ros2 run suspension_tuning <node>``.
"""

from __future__ import annotations

import argparse
import sys
import threading
from collections.abc import Mapping

import rclpy
from rclpy.executors import (
    Executor,
    SingleThreadedExecutor,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

from suspension_tuning.nodes._service_thread import ServiceLoop
from suspension_tuning.nodes._spin import spin_until_shutdown


def build_nodes(workers: int = 1, record: bool = True, context=None,
                overrides: Mapping[str, list[Parameter]] | None = None) -> list[Node]:
    """Create the graph's nodes (not spinning).

    Parameters
    ----------
    workers : int
        Number of simulation workers; 1 keeps the default name ``full_vehicle_sim``.
    record : bool
        Add the recorder node (one bag per optimisation run).
    context : rclpy.context.Context, optional
        Context of the nodes (tests use their own).
    overrides : mapping of node name to list of Parameter, optional
        Parameters set on a node (e.g. ``{'recorder': [Parameter('output_dir', ...)]}``),
        over those the graph sets; ``--params-file`` applies below both.
    """
    from suspension_tuning.nodes.coordinator import CoordinatorNode
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode
    from suspension_tuning.nodes.gradient_evaluator import GradientEvaluatorNode
    from suspension_tuning.nodes.valve_controller import ValveControllerNode

    if workers < 1:
        raise ValueError(f'need at least one simulation worker, got {workers}')
    names = ['full_vehicle_sim'] if workers == 1 else [f'sim_{i}' for i in range(workers)]
    # The first worker's evaluate, the gradient evaluator's services and the
    # coordinator's action server and goals share one thread, so that the models run
    # on one thread, as in-process, and calls among them need no hand-over
    # (model_service_loop).
    loop = model_service_loop(context)
    overrides = overrides or {}

    def params(name: str, *graph_set: Parameter) -> list[Parameter]:
        return [*graph_set, *overrides.get(name, [])]

    nodes: list[Node] = [FullVehicleSimNode(name, context=context,
                                            service_loop=loop if i == 0 else None,
                                            parameter_overrides=params(name))
                         for i, name in enumerate(names)]
    nodes.append(GradientEvaluatorNode(context=context, service_loop=loop,
                                       parameter_overrides=params(
                                           'gradient_evaluator',
                                           Parameter('sim_service',
                                                     value=f'/{names[0]}/evaluate'))))
    nodes.append(ValveControllerNode(context=context,
                                     parameter_overrides=params('valve_controller')))
    nodes.append(CoordinatorNode(context=context, goal_loop=loop, parameter_overrides=params(
        'coordinator', Parameter('sim_workers', value=[f'/{name}' for name in names]))))
    if record:
        from suspension_tuning.nodes.recorder import RecorderNode
        nodes.append(RecorderNode(context=context, parameter_overrides=params('recorder')))
    return nodes


def model_service_loop(context=None) -> ServiceLoop:
    """The one thread of the models' services and the coordinator's goals.

    It serves the first simulation worker's ``evaluate``, the gradient evaluator's
    ``gradient`` and ``calibrate`` and the coordinator's action server, and runs the
    coordinator's goals (a goal is taken, accepted and started on this thread).
    Both models then run on one thread and share numba's OpenMP team, which stays
    awake between them as in an in-process run; on two threads the gradient's team
    sleeps through each full-model run, and each 4-design simplified batch took
    1.5 ms longer (4.2 against 2.6-2.7 ms, ``benchmarks/bench_model_threads.py``).
    A goal (or a calibration) waiting for one of the loop's services answers the
    request itself (``_service_calls.ServiceCaller``), through the middleware as
    before, with no thread to wake.  The loop stops when its services are gone.
    """
    return ServiceLoop(context or rclpy.utilities.get_default_context(), 'models')


class SpinningGraph:
    """The graph's nodes spinning in background threads, one executor per node.

    Every node gets a SingleThreadedExecutor: none of their callbacks waits on
    another callback of the same executor (the hot services are served outside the
    executors, ``nodes/_service_thread.py``; service calls take their own responses,
    ``_service_calls.ServiceCaller``; the coordinator's goals run on goal threads of
    their own), and a callback then runs in the thread that took its request, with
    no hand-over to a thread pool.  Measured on the 2-variable ride optimisation
    (``benchmarks/bench_graph.py``): one shared MultiThreadedExecutor added 56 ms to
    a 0.95 s run, one executor per node 38 ms; the coordinator's goal starts 1.3 ms
    sooner on a SingleThreadedExecutor than on a MultiThreadedExecutor.  Separate
    executors also keep a telemetry burst for the recorder and the step-locked valve
    controller from waiting behind other nodes' callbacks.  :meth:`shutdown` stops
    the executors, joins the threads and destroys the nodes (the recorder finalises
    its bag).
    """

    def __init__(self, nodes: list[Node], extra: list[Node] = ()) -> None:
        self.nodes = [*nodes, *extra]
        self.executors: list[Executor] = []
        for node in self.nodes:
            executor = SingleThreadedExecutor(context=node.context)
            executor.add_node(node)
            self.executors.append(executor)
        self.threads = [threading.Thread(target=self._spin, args=(e,), daemon=True)
                        for e in self.executors]
        for thread in self.threads:
            thread.start()

    @staticmethod
    def _spin(executor: Executor) -> None:
        spin_until_shutdown(executor)

    def wait(self) -> None:
        """Block until the executors stop (Ctrl-C raises KeyboardInterrupt here)."""
        for thread in self.threads:
            while thread.is_alive():
                thread.join(timeout=0.5)

    def shutdown(self) -> None:
        """Stop spinning and destroy the nodes."""
        for executor in self.executors:
            executor.shutdown(timeout_sec=10.0)
        for thread in self.threads:
            thread.join(timeout=10.0)
        for node in reversed(self.nodes):
            node.destroy_node()


def main(argv: list[str] | None = None) -> None:
    """Entry point of ``ros2 run suspension_tuning graph``."""
    argv = sys.argv if argv is None else ['graph', *argv]
    parser = argparse.ArgumentParser(prog='graph', description=__doc__.split('\n')[0])
    parser.add_argument('--workers', type=int, default=1, help='simulation workers')
    parser.add_argument('--no-record', action='store_true', help='no recorder node')
    args = parser.parse_args(rclpy.utilities.remove_ros_args(argv)[1:])
    rclpy.init(args=argv)
    graph = SpinningGraph(build_nodes(args.workers, not args.no_record))
    try:
        graph.wait()
    except KeyboardInterrupt:
        pass
    finally:
        graph.shutdown()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
