"""ROS 2 node ``coordinator``: the Dynamic-Q optimisation as an action server.

Action ``~/optimise`` (Optimise): scenario, 2 or 4 variables, start point, gradient
source 'simplified' or 'full', limits.  Each iteration asks the simulation workers
(``/<worker>/evaluate``) for the full-model objective and constraints and the
gradient evaluator (``<gradient_node>/gradient``) for the scaled simplified-model
gradient, or the workers for 2n full-model central differences.  Before a run with
simplified gradients the gradient evaluator is calibrated (eq. 25, ``calibrate``).

Feedback every iteration; the result holds the optimum (also in physical units), the
history and the full-model, simplified-model and calibration run counts.  The run's
configuration is published on ``/optimisation/run_config`` when a goal starts, every
iteration on ``/optimisation/progress`` and the result on ``/optimisation/result``, so
that the recorder puts one run in one bag.  The loop itself is
:func:`suspension_tuning.tuning.optimise`, shared with in-process runs.
"""

from __future__ import annotations

import json
import subprocess
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import numpy as np
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Task
from std_msgs.msg import String
from suspension_tuning_interfaces.action import Optimise
from suspension_tuning_interfaces.msg import IterationRecord, TimeHistories
from suspension_tuning_interfaces.srv import Calibrate, EvaluateGradient

from suspension_tuning.nodes import _logging
from suspension_tuning.nodes._service_calls import (
    ServiceCaller,
    ServiceCallError,
    SimulationPool,
)
from suspension_tuning.nodes._service_thread import LoopActionServer, ServiceLoop
from suspension_tuning.nodes._spin import run_node
from suspension_tuning.optim.dynamic_q import load_options
from suspension_tuning.paths import config_dir, dump_yaml, read_yaml
from suspension_tuning.tuning import (
    FullEvaluation,
    RunCounter,
    TuningRequest,
    optimise,
    physical_settings,
)

CONFIG_DIR = config_dir()
#: Latched: a late subscriber (the recorder) still gets the run's configuration/result.
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


def code_version() -> str:
    """``git describe`` of the source tree, or the package version outside git."""
    try:
        return subprocess.run(['git', 'describe', '--always', '--dirty', '--tags'],
                              cwd=CONFIG_DIR.parent, capture_output=True, text=True,
                              timeout=5, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        from suspension_tuning import __version__
        return __version__


def configuration_yaml() -> str:
    """The part of a run's configuration that is the same for every run, as YAML.

    Every ``config/*.yaml`` file (the vehicle, the models, the optimiser and the other
    nodes' parameter files) and the code version: what a bag needs to say which model
    produced it.  YAML in pure Python costs tens of ms, so callers dump it once.
    """
    files = {path.name: read_yaml(path) for path in sorted(CONFIG_DIR.glob('*.yaml'))}
    return dump_yaml({'vehicle_configuration': files, 'code_version': code_version()})


def record_to_msg(record: dict[str, Any], counter: RunCounter, t0: float) -> IterationRecord:
    """An optimiser history record as an IterationRecord message."""
    return IterationRecord(
        iteration=int(record['iteration']), x=np.asarray(record['x'], float).tolist(),
        f=float(record['f']), g=np.asarray(record['g'], float).tolist(),
        move_limit=float(record['rho']), move_limit_next=float(record['rho_next']),
        max_violation=float(record['max_violation']),
        n_full_runs=counter.full_runs, n_simplified_runs=counter.simplified_runs,
        wall_time_s=time.monotonic() - t0)


class GoalThreadActionServer(ActionServer):
    """rclpy's ActionServer, with each goal executed on a thread chosen by the node.

    rclpy (Jazzy) runs a goal's execute callback as a task of the node's executor, so
    an optimisation that runs for minutes needs a MultiThreadedExecutor to keep
    cancel, goal and parameter requests answered, and every callback of the node
    then pays a hand-over to a thread of its pool.  Here the executor (single
    threaded) takes the goal, and rclpy's own execution coroutine (which runs the
    callback, sets the goal's result and answers the result requests) runs in
    ``run_goal``; the execute callback is synchronous, so the coroutine ends in one
    step.  In the graph of ``graph.build_nodes`` the model loop takes the goal instead
    of the executor (``_service_thread.LoopActionServer``) and runs it too: the goal
    started 1.4 ms after it was sent, against 1.7 ms with the executor taking it
    and 2.4 ms through a MultiThreadedExecutor
    (``benchmarks/bench_graph_timeline.py``, ``goal_to_execute_ms``).

    Parameters
    ----------
    *args, **kwargs
        As for ``rclpy.action.ActionServer``.
    run_goal : callable
        ``run_goal(task)`` calls ``task()`` on the thread that is to run the goal.
    """

    def __init__(self, *args: Any, run_goal: Callable[[Task], Any], **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._run_goal = run_goal

    def notify_execute(self, goal_handle: Any, execute_callback: Callable | None) -> None:
        """Hand the goal's execution to ``run_goal`` (rclpy: an executor task)."""
        callback = execute_callback or self._execute_callback
        if callback is not None:
            self._run_goal(Task(self._execute_goal, (callback, goal_handle)))

    def add_future(self, future: Any) -> None:
        """Keep a goal's result future away from the executor.

        rclpy registers it so that the executor runs its done callback (sending the
        result to the clients that asked for it) as a task, after a wake-up of its
        own.  Unregistered, the callback runs on the goal's thread as the goal ends,
        or on the executor's thread when a result request comes after the end.
        """

    def remove_future(self, future: Any) -> None:
        """Nothing to remove (see :meth:`add_future`)."""


class CoordinatorNode(Node):
    """Action server ``optimise`` over the simulation workers and gradient evaluator.

    Parameters
    ----------
    goal_loop : ServiceLoop, optional
        Run goals on this loop's thread, and answer its requests while a goal waits
        for a response (``graph.build_nodes``: the loop serving the models, so that
        the coordinator's calls to them need no hand-over between threads).  By
        default goals run on goal threads of the node's own (up to four at once).
    **kwargs
        As for ``rclpy.node.Node``.
    """

    def __init__(self, goal_loop: ServiceLoop | None = None, **kwargs) -> None:
        super().__init__('coordinator', **kwargs)
        self.declare_parameter('sim_workers', ['/full_vehicle_sim'])
        self.declare_parameter('gradient_node', '/gradient_evaluator')
        self.declare_parameter('call_timeout_s', 600.0)
        self.declare_parameter('calibration_samples', 30)
        self.declare_parameter('fd_step', 0.025)
        self.declare_parameter('optimiser_config', '')
        self.declare_parameter('optimiser_section', 'vehicle')
        # One more full run at the optimum, publishing its telemetry for the bag; a
        # recording run, not part of the optimisation's run counts.
        self.declare_parameter('final_telemetry', True)
        # Seconds a goal's result is kept for late result requests after the goal ends
        # (rcl's default 900 s).  Every status message carries every goal kept, and an
        # action client converts all of them each time (config/graph.yaml).
        self.declare_parameter('result_timeout_s', 10.0)
        group = ReentrantCallbackGroup()
        self.timeout_s = float(self.get_parameter('call_timeout_s').value)
        self.goal_loop = goal_loop
        self.goal_threads = ThreadPoolExecutor(max_workers=4, thread_name_prefix='optimise')
        self.goals: list[Future] = []
        self.caller = ServiceCaller(self, serve_loop=goal_loop)
        self.pool = SimulationPool(self.caller, list(self.get_parameter('sim_workers').value),
                                   self.timeout_s)
        gradient_node = str(self.get_parameter('gradient_node').value).rstrip('/')
        self.gradient_client = self.caller.create_client(EvaluateGradient,
                                                         f'{gradient_node}/gradient')
        self.calibrate_client = self.caller.create_client(Calibrate,
                                                          f'{gradient_node}/calibrate')
        config = str(self.get_parameter('optimiser_config').value) or str(
            CONFIG_DIR / 'optimiser.yaml')
        self.options = load_options(config, str(self.get_parameter('optimiser_section').value))
        self.progress_pub = self.create_publisher(IterationRecord, '/optimisation/progress',
                                                  RELIABLE)
        self.config_pub = self.create_publisher(String, '/optimisation/run_config', LATCHED)
        self.result_pub = self.create_publisher(Optimise.Result, '/optimisation/result',
                                                LATCHED)
        # Dumped once: the configuration a run records does not change while the node runs.
        self.static_config_yaml = configuration_yaml()
        # (JSON form, YAML text) of the last run configuration published.
        self._config_yaml: tuple[str, str] = ('', '')
        self.server = GoalThreadActionServer(
            self, Optimise, '~/optimise', execute_callback=self._execute,
            goal_callback=lambda _: GoalResponse.ACCEPT,
            cancel_callback=lambda _: CancelResponse.ACCEPT, callback_group=group,
            result_timeout=float(self.get_parameter('result_timeout_s').value),
            run_goal=self._run_goal)
        # On the goal loop, the loop takes the goal, cancel and result requests too.
        self.served_action = (None if goal_loop is None else LoopActionServer(
            self, self.server, f'{self.get_fully_qualified_name()}/optimise', goal_loop))

    def _run_goal(self, task: Task) -> None:
        """Start a goal on the goal loop, or on a goal thread (loop stopped or none)."""
        future = None
        if self.goal_loop is not None:
            try:
                future = self.goal_loop.submit(self._execute_task, task)
            except RuntimeError:  # the loop has stopped: a goal thread instead
                pass
        if future is None:
            future = self.goal_threads.submit(self._execute_task, task)
        self.goals = [goal for goal in self.goals if not goal.done()] + [future]

    # ------------------------------------------------------------------ helpers
    def _request(self, goal: Optimise.Goal) -> TuningRequest:
        options = self.options.as_dict()
        if goal.max_iterations:
            options['maxiter'] = int(goal.max_iterations)
        if goal.move_limit:
            options['rho0'] = float(goal.move_limit)
        return TuningRequest(goal.scenario, int(goal.n_vars), list(goal.x0) or None,
                             goal.gradient_source or 'simplified', options,
                             float(self.get_parameter('fd_step').value), goal.integrator)

    def _publish_run_config(self, request: TuningRequest) -> None:
        config = {
            'scenario': request.scenario, 'n_vars': request.n_vars,
            'x0': request.start.tolist(), 'gradient_source': request.gradient_source,
            'optimiser_options': request.options, 'fd_step': request.fd_step,
            'integrator': request.integrator or 'simulation default',
            'coordinator_parameters': {name: p.value for name, p in
                                       self.get_parameters_by_prefix('').items()},
        }
        # Goals of one node mostly repeat their configuration, and the YAML emitter
        # (libyaml's, through PyYAML's representers) takes ~0.25 ms even warm: the text
        # of a configuration is kept, keyed by its JSON form.  The start time is the
        # one line that always changes (a float's YAML form is its repr, as PyYAML's).
        key = json.dumps(config, default=repr)
        if self._config_yaml[0] != key:
            self._config_yaml = (key, dump_yaml(config))
        text = self._config_yaml[1]
        stamp = f'started_unix_s: {time.time()!r}\n'
        self.config_pub.publish(String(data=text + stamp + self.static_config_yaml))

    def _full_model(self, request: TuningRequest):
        def evaluate(designs: np.ndarray) -> FullEvaluation:
            # The simplified handling model runs on the inputs of the full run at x
            # (simplified_inputs.py); the ride model needs none.
            responses = self.pool.evaluate(
                request.scenario, request.n_vars, designs,
                return_inputs=(request.gradient_source == 'simplified' and len(designs) == 1
                               and request.scenario == 'handling'),
                integrator=request.integrator)
            f = np.concatenate([np.asarray(r.f, float) for r in responses])
            g = np.concatenate([np.asarray(r.g, float).reshape(r.n_designs, r.n_constraints)
                                for r in responses])
            inputs = responses[0].inputs[0] if responses[0].inputs else None
            return FullEvaluation(f=f, g=g, inputs=inputs)
        return evaluate

    def _simplified_gradient(self, request: TuningRequest):
        def gradient(x: np.ndarray, inputs: Any) -> tuple[np.ndarray, np.ndarray]:
            response = self.caller.call(self.gradient_client, EvaluateGradient.Request(
                scenario=request.scenario, n_vars=request.n_vars, x=x.tolist(),
                step=request.fd_step,
                inputs=TimeHistories() if inputs is None else inputs), self.timeout_s)
            if not response.success:
                raise ValueError(f'gradient evaluator: {response.error}')
            dg = np.asarray(response.dg, float).reshape(response.n_constraints, request.n_vars)
            return np.asarray(response.df, float), dg
        return gradient

    def _calibrate(self, request: TuningRequest) -> Calibrate.Response:
        response = self.caller.call(self.calibrate_client, Calibrate.Request(
            scenario=request.scenario, n_vars=request.n_vars,
            n_samples=int(self.get_parameter('calibration_samples').value), force=False,
            integrator=request.integrator),
            self.timeout_s * 2)
        if not response.success:
            raise ValueError(f'calibration failed: {response.error}')
        return response

    # ------------------------------------------------------------------ action
    def _execute_task(self, task: Task) -> None:
        """Run rclpy's execution coroutine of one goal (on the goal's thread)."""
        task()
        error = task.exception() if task.done() else RuntimeError('goal suspended')
        if error is not None and self.context.ok():  # after shutdown: nothing to report to
            self.get_logger().error(f'goal execution failed: {type(error).__name__}: {error}')

    def _execute(self, goal_handle) -> Optimise.Result:
        """The action's execute callback: :meth:`_optimise`, quiet when ROS shuts down.

        Ctrl-C on a process holding the graph (``graph``, ``make demo``) shuts the
        context down under a running goal: its next service call, status or result
        fails.  The goal then ends with this result, which no client can receive any
        more, instead of a traceback.
        """
        try:
            return self._optimise(goal_handle)
        except Exception as error:
            if self.context.ok():
                raise
            return Optimise.Result(success=False, message='stopped: ROS shut down under the '
                                   f'goal ({type(error).__name__}: {error})')

    def _optimise(self, goal_handle) -> Optimise.Result:
        t0 = time.monotonic()
        try:
            request = self._request(goal_handle.request)
        except ValueError as error:
            goal_handle.abort()
            return Optimise.Result(success=False, message=f'bad goal: {error}')
        if goal_handle.is_cancel_requested:  # cancelled while it waited for an earlier goal
            goal_handle.canceled()
            return Optimise.Result(success=False, message='cancelled before it started')
        _logging.info(self, f'optimising {request.scenario} with {request.n_vars} '
                            f'variables, {request.gradient_source} gradients')
        self._publish_run_config(request)
        counter = RunCounter()
        history_msgs: list[IterationRecord] = []

        def on_iteration(record: dict[str, Any], counts: RunCounter) -> bool:
            msg = record_to_msg(record, counts, t0)
            history_msgs.append(msg)
            goal_handle.publish_feedback(Optimise.Feedback(latest=msg))
            self.progress_pub.publish(msg)
            return goal_handle.is_cancel_requested

        try:
            if request.gradient_source == 'simplified':
                counter.calibration_runs = int(self._calibrate(request).n_full_runs)
            result = optimise(request, self._full_model(request),
                              self._simplified_gradient(request), on_iteration,
                              counter=counter)
        except (ValueError, ServiceCallError) as error:
            self.get_logger().error(f'optimisation failed: {error}')
            goal_handle.abort()
            message = Optimise.Result(success=False, message=str(error), history=history_msgs,
                                      wall_time_s=time.monotonic() - t0, **counter.as_dict())
            self.result_pub.publish(message)
            return message
        physical = physical_settings(result.x)
        if self.get_parameter('final_telemetry').value and not goal_handle.is_cancel_requested:
            try:
                self.pool.evaluate(request.scenario, request.n_vars, result.x[None, :],
                                   publish_telemetry=True)
            except (ValueError, ServiceCallError) as error:
                self.get_logger().warning(f'telemetry run of the optimum failed: {error}')
        message = Optimise.Result(
            success=bool(result.success), message=str(result.message),
            x=np.asarray(result.x, float).tolist(), f=float(result.f),
            g=np.asarray(result.g, float).tolist(), physical_names=list(physical),
            physical_values=list(physical.values()), iterations=int(result.nit),
            history=history_msgs, wall_time_s=time.monotonic() - t0, **counter.as_dict())
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
            message.message = 'cancelled'
        else:
            goal_handle.succeed()
        self.result_pub.publish(message)
        return message

    def destroy_node(self) -> None:
        """Destroy the action server and the private clients too, after goals end (10 s).

        rclpy's ``Node.destroy_node`` leaves action servers alone: the server's handles
        keep the node's DDS participant alive, and other processes go on seeing an
        ``optimise`` action that never answers.
        """
        for goal in self.goals:
            if not goal.done():
                try:
                    goal.result(timeout=10.0)
                except Exception:  # noqa: BLE001 - ended or stuck: destroyed all the same
                    pass
        self.goal_threads.shutdown(wait=False, cancel_futures=True)
        if self.served_action is not None:
            self.served_action.destroy()
        self.server.destroy()
        self.caller.destroy()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run suspension_tuning coordinator``."""
    run_node(CoordinatorNode, args, multithreaded=False)


if __name__ == '__main__':
    main()
