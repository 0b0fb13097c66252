"""The tuning graph in one process for a test, and the bags it records.

The graph's nodes come from :func:`suspension_tuning.graph.build_nodes` (simulation
workers, gradient evaluator, valve controller, coordinator, optionally the recorder);
any of them can be replaced by the test's own node of the same name, and each node
spins on an executor of its own (:class:`~suspension_tuning.testing.SpinningExecutor`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

from rclpy.action import ActionClient
from rclpy.context import Context
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from suspension_tuning.bag.reader import BagContents, read_messages
from suspension_tuning.testing._ros import (
    DEFAULT_SERVER_TIMEOUT_S,
    DEFAULT_TIMEOUT_S,
    RosTimeoutError,
    SpinningExecutor,
    call_service,
    isolated_context,
    raise_callback_errors,
    send_goal,
    wait_until,
)

#: The coordinator's action, as ``build_nodes`` names it.
OPTIMISE_ACTION = '/coordinator/optimise'
#: Topics the recorder must subscribe to before a run, so that the run gets its own
#: bag: the run configuration opens the bag, the result closes it.
RUN_TOPICS = ('/optimisation/run_config', '/optimisation/result')
#: A node factory: called as ``factory(context=..., [parameter_overrides=...])``,
#: for example the node's class.
NodeFactory = Callable[..., Node]


def _parameters(values: Mapping[str, Any]) -> list[Parameter]:
    return [value if isinstance(value, Parameter) else Parameter(name, value=value)
            for name, value in values.items()]


def bag_folders(directory: str | Path) -> tuple[list[Path], list[Path]]:
    """(closed, open) bag folders under ``directory``; closed ones oldest first.

    A bag folder is closed once its ``metadata.yaml`` is written (the writer's last
    step, ``BagWriter.close``); before that it holds only its ``.mcap`` file.
    """
    directory = Path(directory)
    if not directory.is_dir():
        return [], []
    folders = [p for p in directory.iterdir() if p.is_dir()]
    closed = [p for p in folders if (p / 'metadata.yaml').is_file()]
    still_open = [p for p in folders if p not in closed and any(p.glob('*.mcap'))]
    closed.sort(key=lambda p: (p / 'metadata.yaml').stat().st_mtime_ns)
    return closed, still_open


def wait_for_bag(directory: str | Path, timeout_s: float = 30.0,
                 known: set[Path] | frozenset[Path] = frozenset()) -> Path:
    """The newest bag under ``directory`` once the recorder has closed every bag.

    Waits until at least one closed bag not in ``known`` exists and no bag is open
    (a run's bag stays open ``post_run_s`` after its result, config/recorder.yaml).

    Raises
    ------
    RosTimeoutError
        If that does not happen within ``timeout_s``; the message lists the folder's
        bags.
    """
    def ready() -> bool:
        closed, still_open = bag_folders(directory)
        return not still_open and any(p not in known for p in closed)

    if not wait_until(ready, timeout_s, period_s=0.1):
        closed, still_open = bag_folders(directory)
        raise RosTimeoutError(
            f'no new closed bag in {directory} within {timeout_s:g} s (closed: '
            f'{[p.name for p in closed]}, still open: {[p.name for p in still_open]})')
    return bag_folders(directory)[0][-1]


def open_bag(path: str | Path) -> BagContents:
    """Every message of a closed bag (:func:`suspension_tuning.bag.reader.read_messages`).

    Raises
    ------
    ValueError
        If the bag does not read to its end (the reason in the message).
    """
    contents = read_messages(path)
    if not contents.complete:
        raise ValueError(f'bag {path} is not complete: {contents.stop_reason}')
    return contents


class TuningGraph:
    """The tuning graph's nodes spinning in this process, plus a client node.

    Parameters
    ----------
    context : rclpy.context.Context
        The context of every node (e.g. from :func:`isolated_context`).
    workers : int
        Simulation workers (``full_vehicle_sim``, or ``sim_0``, ``sim_1``, ...).
    record_dir : str or Path, optional
        Add the recorder, writing its bags (one per optimisation run) here.
    replace : mapping of node name to node factory, optional
        Nodes of the graph replaced by the test's own: ``{'valve_controller':
        MyValveController}`` creates ``MyValveController(context=context,
        parameter_overrides=[...])`` in place of the package's valve controller
        (``graph.build_nodes(factories=...)``); the overrides hold what ``parameters``
        sets on that node.
    parameters : mapping of node name to {parameter: value}, optional
        ROS parameters set on the graph's nodes, over those the graph sets
        (``{'coordinator': {'calibration_samples': 12}}``).
    calibration_dir : str or Path, optional
        Where the gradient evaluator caches its eq. 25 calibrations; by default the
        node's own (``~/.cache/suspension_tuning/calibration``), shared with other
        runs.
    num_threads : int
        Threads of the executor of each node that asks for a
        ``MultiThreadedExecutor`` (its class attribute ``EXECUTOR``, as ``ros2 run``
        spins it); the other nodes, a test's own without the attribute among them,
        get a SingleThreadedExecutor as they do there.  1: single-threaded throughout.
    ready_timeout_s : float
        Longest wait for the recorder to subscribe to the run topics, s.

    Raises
    ------
    ValueError
        If ``replace`` or ``parameters`` names a node that is not in the graph.
    RosTimeoutError
        If the recorder does not subscribe to the run topics in time.
    """

    def __init__(self, context: Context, workers: int = 1,
                 record_dir: str | Path | None = None,
                 replace: Mapping[str, NodeFactory] | None = None,
                 parameters: Mapping[str, Mapping[str, Any]] | None = None,
                 calibration_dir: str | Path | None = None, num_threads: int = 4,
                 ready_timeout_s: float = DEFAULT_SERVER_TIMEOUT_S) -> None:
        from suspension_tuning.graph import build_nodes

        self.context = context
        self.record_dir = None if record_dir is None else Path(record_dir)
        parameters = {name: dict(values) for name, values in (parameters or {}).items()}
        if self.record_dir is not None:
            parameters.setdefault('recorder', {}).setdefault('output_dir', str(self.record_dir))
        if calibration_dir is not None:
            parameters.setdefault('gradient_evaluator', {}).setdefault(
                'calibration_dir', str(calibration_dir))
        overrides = {name: _parameters(values) for name, values in parameters.items()}
        replace = dict(replace or {})
        self.spinners: list[SpinningExecutor] = []
        self.nodes: dict[str, Node] = {}
        self._bags_opened: set[Path] = set()
        self._clients: dict[tuple[str, type], Any] = {}
        built = build_nodes(workers=workers, record=self.record_dir is not None,
                            context=context, overrides=overrides, factories=replace)
        try:
            names = [node.get_name() for node in built]
            unknown = sorted(set(parameters) - set(names))
            if unknown:
                raise ValueError(f'no node named {unknown} in the graph to set parameters on '
                                 f'(its nodes: {names})')
            self.nodes = {node.get_name(): node for node in built}
            self.client_node = Node('tuning_graph_test_client', context=context)
        except BaseException:
            for node in built:
                node.destroy_node()
            raise
        try:
            for node in [*self.nodes.values(), self.client_node]:
                self.add(node, num_threads=num_threads)
            if self.record_dir is not None:
                self._wait_for_recorder(ready_timeout_s)
        except BaseException:
            self.shutdown()
            raise

    def add(self, node: Node, num_threads: int = 4) -> Node:
        """Spin ``node`` on an executor of its own; it is destroyed with the graph.

        The executor is of the kind the node asks for (class attribute ``EXECUTOR``,
        default single-threaded), with ``num_threads`` threads when multi-threaded.
        A step-locked node (the valve controller) answers each message before the
        next comes: on a multi-threaded executor every answer is handed to a pool
        thread, and on 2 cores shared with the integrating thread the round trip
        took 4-50 ms at the median and over 0.4 s for one in ten (against 0.4-0.7
        ms single-threaded), so a mixed run over topics timed out.
        """
        kind = getattr(node, 'EXECUTOR', SingleThreadedExecutor)
        threads = num_threads if issubclass(kind, MultiThreadedExecutor) else 1
        spinner = SpinningExecutor(self.context, threads, name=f'spin_{node.get_name()}')
        spinner.add(node)
        self.spinners.append(spinner)
        return node

    def node(self, name: str) -> Node:
        """The graph's node called ``name`` (``coordinator``, ``valve_controller``, ...)."""
        try:
            return self.nodes[name]
        except KeyError:
            raise KeyError(f'no node {name!r} in the graph (its nodes: '
                           f'{sorted(self.nodes)})') from None

    def _wait_for_recorder(self, timeout_s: float) -> None:
        recorder = self.node('recorder').get_name()

        def subscribed(topic: str) -> bool:
            return any(info.node_name == recorder
                       for info in self.client_node.get_subscriptions_info_by_topic(topic))

        if not wait_until(lambda: all(subscribed(t) for t in RUN_TOPICS), timeout_s):
            missing = [t for t in RUN_TOPICS if not subscribed(t)]
            raise RosTimeoutError(f'the recorder did not subscribe to {missing} within '
                                  f'{timeout_s:g} s')

    # ------------------------------------------------------------- requests
    def _client(self, kind: type, name: str, make: Callable[[], Any]) -> Any:
        key = (name, kind)
        if key not in self._clients:
            self._clients[key] = make()
        return self._clients[key]

    def call(self, srv_type: type, service: str, request: Any,
             timeout_s: float = DEFAULT_TIMEOUT_S) -> Any:
        """Call ``service`` from the client node and return the response.

        Raises
        ------
        RosTimeoutError
            If the service is not found or does not answer within ``timeout_s``
            (the message names it).
        """
        client = self._client(srv_type, service,
                              lambda: self.client_node.create_client(srv_type, service))
        return call_service(client, request, timeout_s)

    def send_goal(self, action_type: type, action: str, goal: Any,
                  timeout_s: float = DEFAULT_TIMEOUT_S,
                  feedback_callback: Callable[[Any], None] | None = None) -> Any:
        """Send a goal to ``action`` and return its :class:`GoalOutcome`.

        Raises
        ------
        RosTimeoutError
            If the server is not found or the goal is not answered in time (the
            message names the action); the goal is then cancelled.
        GoalRejectedError
            If the server rejected the goal.
        """
        client = self._client(action_type, action,
                              lambda: ActionClient(self.client_node, action_type, action))
        return send_goal(client, goal, timeout_s, feedback_callback, action_name=action)

    def optimise(self, scenario: str = 'ride', n_vars: int = 2,
                 gradient_source: str = 'simplified', timeout_s: float = DEFAULT_TIMEOUT_S,
                 feedback_callback: Callable[[Any], None] | None = None,
                 action: str = OPTIMISE_ACTION, **goal_fields: Any) -> Any:
        """Run one Dynamic-Q optimisation through the coordinator; its Optimise.Result.

        Parameters
        ----------
        scenario, n_vars, gradient_source, **goal_fields
            Fields of the Optimise goal (``x0``, ``max_iterations``, ``move_limit``).
        timeout_s : float
            Longest wait for the goal to be accepted, then for its result, s.
        feedback_callback : callable, optional
            Called with each iteration's Optimise.Feedback.
        action : str
            The coordinator's action.

        Raises
        ------
        RosTimeoutError
            If the coordinator is not found or the goal does not end in time.
        """
        from suspension_tuning_interfaces.action import Optimise

        goal = Optimise.Goal(scenario=scenario, n_vars=n_vars,
                             gradient_source=gradient_source, **goal_fields)
        return self.send_goal(Optimise, action, goal, timeout_s, feedback_callback).result

    # ------------------------------------------------------------- bags
    def recorded_bag(self, timeout_s: float = 30.0) -> BagContents:
        """The bag of the run just recorded, once the recorder has closed it.

        Each call waits for a bag not returned before (:func:`wait_for_bag`).

        Raises
        ------
        RuntimeError
            If the graph has no recorder.
        RosTimeoutError
            If no new bag is closed within ``timeout_s``.
        """
        if self.record_dir is None:
            raise RuntimeError('this graph records no bags: start it with a record_dir')
        path = wait_for_bag(self.record_dir, timeout_s, known=self._bags_opened)
        self._bags_opened.add(path)
        return open_bag(path)

    # ------------------------------------------------------------- end
    @property
    def errors(self) -> list[BaseException]:
        """Exceptions raised by callbacks of the graph's executors so far."""
        return [error for spinner in self.spinners for error in spinner.errors]

    def shutdown(self) -> None:
        """Stop every executor, then destroy the nodes (the recorder closes its bag)."""
        for spinner in self.spinners:
            spinner.stop()
        for spinner in reversed(self.spinners):
            spinner.shutdown()  # already stopped: destroys its node


@contextmanager
def tuning_graph(context: Context | None = None, **options: Any) -> Iterator[TuningGraph]:
    """A :class:`TuningGraph` (same options), shut down after the block.

    Without ``context``, the graph gets an :func:`isolated_context` of its own, on the
    process's domain, reserved on the machine while the block runs.

    Raises
    ------
    CallbackError
        After the block, if a callback raised while spinning (and the block did not).

    Examples
    --------
    >>> with tuning_graph(record_dir='/tmp/bags') as graph:          # doctest: +SKIP
    ...     result = graph.optimise('ride', 2)
    ...     bag = graph.recorded_bag()
    """
    with ExitStack() as stack:
        if context is None:
            context = stack.enter_context(isolated_context())
        graph = TuningGraph(context, **options)
        try:
            yield graph
        finally:
            graph.shutdown()
        raise_callback_errors(graph.errors)
