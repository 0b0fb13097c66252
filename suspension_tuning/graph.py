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

import rclpy
from rclpy.executors import (
    Executor,
    MultiThreadedExecutor,
    SingleThreadedExecutor,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

from suspension_tuning.nodes._service_thread import ServiceLoop
from suspension_tuning.nodes._spin import spin_until_shutdown


def build_nodes(workers: int = 1, record: bool = True, context=None,
                recorder_overrides: list[Parameter] | None = None) -> list[Node]:
    """Create the graph's nodes (not spinning).

    Parameters
    ----------
    workers : int
        Number of simulation workers; 1 keeps the default name ``full_vehicle_sim``.
    record : bool
        Add the recorder node (one bag per optimisation run).
    context : rclpy.context.Context, optional
        Context of the nodes (tests use their own).
    recorder_overrides : list of Parameter, optional
        Parameters of the recorder (e.g. its output folder).
    """
    from suspension_tuning.nodes.coordinator import CoordinatorNode
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode
    from suspension_tuning.nodes.gradient_evaluator import GradientEvaluatorNode
    from suspension_tuning.nodes.valve_controller import ValveControllerNode

    if workers < 1:
        raise ValueError(f'need at least one simulation worker, got {workers}')
    names = ['full_vehicle_sim'] if workers == 1 else [f'sim_{i}' for i in range(workers)]
    # The first worker's evaluate and the gradient share one serving thread, so that
    # the models run on one thread, as in-process (nodes/_service_thread.py).
    loop = model_service_loop(context)
    nodes: list[Node] = [FullVehicleSimNode(name, context=context,
                                            service_loop=loop if i == 0 else None)
                         for i, name in enumerate(names)]
    worker_param = Parameter('sim_workers', value=[f'/{name}' for name in names])
    nodes.append(GradientEvaluatorNode(
        context=context, service_loop=loop,
        parameter_overrides=[Parameter('sim_service', value=f'/{names[0]}/evaluate')]))
    nodes.append(ValveControllerNode(context=context))
    nodes.append(CoordinatorNode(context=context, parameter_overrides=[worker_param]))
    if record:
        from suspension_tuning.nodes.recorder import RecorderNode
        nodes.append(RecorderNode(context=context,
                                  parameter_overrides=recorder_overrides or []))
    return nodes


def model_service_loop(context=None) -> ServiceLoop:
    """The loop serving the first simulation worker's ``evaluate`` and the gradient.

    Both models then run on one thread and share numba's OpenMP team, which stays
    awake between them as in an in-process run; on two threads the gradient's team
    sleeps through each full-model run, and each 4-design simplified batch took
    1.5 ms longer (4.2 against 2.6-2.7 ms, ``benchmarks/bench_model_threads.py``).
    The loop stops when both services are gone.
    """
    return ServiceLoop(context or rclpy.utilities.get_default_context(), 'models')


class SpinningGraph:
    """The graph's nodes spinning in background threads, one executor per node.

    Every node but the coordinator gets a SingleThreadedExecutor: none of their
    callbacks waits on another callback of the same executor (the hot services are
    served outside the executors, ``nodes/_service_thread.py``, and service calls
    take their own responses, ``_service_calls.ServiceCaller``), and a callback then
    runs in the thread that took its request, with no hand-over to a thread pool.
    Measured on the 2-variable ride optimisation (``benchmarks/bench_graph.py``):
    one shared MultiThreadedExecutor added 56 ms to
    a 0.95 s run, one executor per node 38 ms.  The coordinator keeps a
    MultiThreadedExecutor: its action's execute callback runs for a whole
    optimisation while goal, cancel and parameter requests must still be served.
    Separate executors also keep a telemetry burst for the recorder and the
    step-locked valve controller from waiting behind other nodes' callbacks.
    :meth:`shutdown` stops the executors, joins the threads and destroys the nodes
    (the recorder finalises its bag).
    """

    def __init__(self, nodes: list[Node], extra: list[Node] = ()) -> None:
        from suspension_tuning.nodes.coordinator import CoordinatorNode

        self.nodes = [*nodes, *extra]
        self.executors: list[Executor] = []
        for node in self.nodes:
            executor = (MultiThreadedExecutor(num_threads=4, context=node.context)
                        if isinstance(node, CoordinatorNode)
                        else SingleThreadedExecutor(context=node.context))
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
