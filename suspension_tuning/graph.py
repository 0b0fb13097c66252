"""``graph``: every node of the tuning graph in one process.

``ros2 run suspension_tuning graph --workers 2`` starts the simulation workers
(``sim_0``, ``sim_1``, ...), the gradient evaluator, the valve controller, the
coordinator and (unless ``--no-record``) the recorder, each node on an executor
of its own.
ROS parameters come from ``--ros-args --params-file config/graph.yaml`` like for any
node.  Each node also runs alone with ``ros2 run suspension_tuning <node>``.

A graph whose node names another node already has on the ROS domain (e.g. a second
``graph`` left running) does not start: one line names those nodes, the domain and
how to pick another (another ``ROS_DOMAIN_ID``, or a namespace ``--ros-args -r
__ns:=/other``), exit code 2 (:mod:`suspension_tuning.nodes._unique`; the check waits
up to 3.5 s for discovery).
"""

from __future__ import annotations

import argparse
import functools
import sys
from collections.abc import Callable, Mapping

import rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter

from suspension_tuning.nodes._spin import (
    SpinningGraph,
    end_rclpy,
    made_or_stopped,
    settle_signal,
)


def worker_names(workers: int) -> list[str]:
    """The simulation workers' node names: ``full_vehicle_sim`` alone, else ``sim_<i>``."""
    return ['full_vehicle_sim'] if workers == 1 else [f'sim_{i}' for i in range(workers)]


def node_names(workers: int = 1, record: bool = True) -> list[str]:
    """The names of the nodes :func:`build_nodes` creates (before remapping)."""
    return [*worker_names(workers), 'gradient_evaluator', 'valve_controller', 'coordinator',
            *(['recorder'] if record else [])]


def build_nodes(workers: int = 1, record: bool = True, context=None,
                overrides: Mapping[str, list[Parameter]] | None = None,
                factories: Mapping[str, Callable[..., Node]] | None = None) -> list[Node]:
    """Create the graph's nodes (not spinning).

    Parameters
    ----------
    workers : int
        Number of simulation workers; 1 keeps the default name ``full_vehicle_sim``;
        0 runs none here (the coordinator and the gradient evaluator use the workers
        they find on the graph, e.g. on other hosts: docs/distributed.md).
    record : bool
        Add the recorder node (one bag per optimisation run).
    context : rclpy.context.Context, optional
        Context of the nodes (tests use their own).
    overrides : mapping of node name to list of Parameter, optional
        Parameters set on a node (e.g. ``{'recorder': [Parameter('output_dir', ...)]}``),
        over those the graph sets; ``--params-file`` applies below both.
    factories : mapping of node name to callable, optional
        A node of one's own in place of the graph's (e.g. ``{'valve_controller':
        MyController}``), called with ``context`` and ``parameter_overrides``
        keywords.  Its class attribute ``EXECUTOR`` names the executor it needs
        (default single-threaded, ``nodes._spin.executor_for``).

    Raises
    ------
    ValueError
        A negative number of workers, or a factory for a node the graph does not have.
    Exception
        What a node's constructor raised (e.g. FmuConfigError for a worker's FMU), with
        the node's name in its attribute ``node_name``; the nodes made before it are
        destroyed.
    """
    from suspension_tuning.nodes.coordinator import CoordinatorNode
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode
    from suspension_tuning.nodes.gradient_evaluator import GradientEvaluatorNode
    from suspension_tuning.nodes.valve_controller import ValveControllerNode

    if workers < 0:
        raise ValueError(f'the number of simulation workers cannot be negative: {workers}')
    names = worker_names(workers)
    makers = {**{name: functools.partial(FullVehicleSimNode, name) for name in names},
              'gradient_evaluator': GradientEvaluatorNode,
              'valve_controller': ValveControllerNode, 'coordinator': CoordinatorNode}
    if record:
        from suspension_tuning.nodes.recorder import RecorderNode
        makers['recorder'] = RecorderNode
    unknown = sorted(set(factories or {}) - set(makers))
    if unknown:
        raise ValueError(f'no node {", ".join(unknown)} in the graph to replace; its nodes: '
                         + ', '.join(makers))
    makers.update(factories or {})
    overrides = overrides or {}
    nodes: list[Node] = []
    for name, make in makers.items():
        try:
            nodes.append(make(context=context, parameter_overrides=overrides.get(name, [])))
        except BaseException as error:  # also Ctrl-C while they are made
            if isinstance(error, Exception):
                error.node_name = name
            for node in reversed(nodes):  # e.g. a worker's FMU child processes
                node.destroy_node()
            raise
    return nodes


def main(argv: list[str] | None = None) -> None:
    """Entry point of ``ros2 run suspension_tuning graph``."""
    argv = sys.argv if argv is None else ['graph', *argv]
    from suspension_tuning.config_check import ConfigError, check_params_files
    try:  # before rcl parses them: a syntax error there ends in its traceback
        check_params_files(argv)
    except ConfigError as error:
        print(f'graph: not started: {error}', file=sys.stderr)
        sys.exit(2)
    parser = argparse.ArgumentParser(prog='graph', description=__doc__.split('\n')[0])
    parser.add_argument('--workers', type=int, default=1,
                        help='simulation workers in this process (0: only those found on the '
                             'graph, e.g. on other hosts)')
    parser.add_argument('--no-record', action='store_true', help='no recorder node')
    parser.add_argument('--telemetry-rate', type=float, default=None, metavar='R',
                        help="live telemetry: the workers' parameter telemetry_rate, a run's "
                             'telemetry paced at its simulated time / R (1.0: as it happened); '
                             '0, the default, publishes it at once (best for optimisation)')
    args = parser.parse_args(rclpy.utilities.remove_ros_args(argv)[1:])
    if args.workers < 0:
        parser.error(f'--workers cannot be negative, got {args.workers}')
    if args.telemetry_rate is not None and not args.telemetry_rate >= 0.0:
        parser.error(f'--telemetry-rate must be 0 (at once) or a positive rate factor, got '
                     f'{args.telemetry_rate:g}')
    rclpy.init(args=argv)
    from suspension_tuning.nodes._unique import require_unique, start_check
    # One discovery window for every node of the graph, spent importing the nodes.
    check = start_check('graph', node_names(args.workers, not args.no_record))
    from suspension_tuning.fmu import FmuConfigError, MappingError
    from suspension_tuning.nodes import (  # noqa: F401 - imported during the window
        coordinator,
        full_vehicle_sim,
        gradient_evaluator,
        recorder,
        valve_controller,
    )
    from suspension_tuning.nodes._parameters import ParameterError
    if not require_unique('graph', check):
        return  # Ctrl-C or SIGTERM during the check: nothing was started
    live = ([] if args.telemetry_rate is None
            else [Parameter('telemetry_rate', value=args.telemetry_rate)])
    # A set-up error as the node alone says it (full_vehicle_sim's main): one line, exit 2.
    nodes = made_or_stopped(
        lambda: build_nodes(args.workers, not args.no_record,
                            overrides={name: live for name in worker_names(args.workers)}),
        (FmuConfigError, MappingError, ParameterError, ConfigError),
        lambda error: getattr(error, 'node_name', 'graph'))
    if nodes is None:
        return  # Ctrl-C or SIGTERM while the nodes were made: the ones made are gone
    try:
        graph = SpinningGraph(nodes)
    except KeyboardInterrupt:  # Ctrl-C while the executors start: no goal ran yet
        settle_signal()
        for node in reversed(nodes):
            node.destroy_node()
        end_rclpy()
        return
    interrupted = False
    try:
        graph.wait()
    except KeyboardInterrupt:
        interrupted = True
    finally:
        graph.shutdown(interrupted)
        end_rclpy()


if __name__ == '__main__':
    main()
