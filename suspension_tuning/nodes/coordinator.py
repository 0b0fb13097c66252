"""ROS 2 node ``coordinator``: the Dynamic-Q optimisation as an action server.

Action ``~/optimise`` (Optimise): scenario, n variables (2 or 4, or the size of a
config/design_space.yaml preset), start point, gradient source 'simplified' or 'full',
limits, and extra constraints on another scenario's
objective or any named metric (``tuning.ConstraintSpec``; their scenarios run on the
same workers, their simplified gradients on the same gradient evaluator).  Each
iteration asks the simulation workers (``/<worker>/evaluate``) for the full-model
objective and constraints and the gradient evaluator (``<gradient_node>/gradient``)
for the scaled simplified-model gradient, or the workers for 2n full-model central
differences.  Before a run with simplified gradients the gradient evaluator is
calibrated (eq. 25, ``calibrate``) for every scenario with simplified terms, with the
``calibration_samples`` parameter's samples or, by default, each case's of
config/simplified_models.yaml ``scaling.run_samples`` (none on the ride: unit scaling,
which the run's first-order correction maps onto the full model; 4 on handling).

Feedback every iteration; the result holds the reported design (the best feasible
iterate, or the least violating one when none was feasible, and says which; also in
physical units), its physical metrics beside those of the baseline design
(config/design_space.yaml; one more full run per goal, not counted in the
optimisation's runs), the history and the full-model, simplified-model and calibration
run counts.  The run's configuration is published on ``/optimisation/run_config`` when a
goal starts, every iteration on ``/optimisation/progress`` and the result on
``/optimisation/result``, so that the recorder puts one run in one bag.  A goal with
gradient source 'evaluate' is one full-model run of its x0 instead, in any full-model
scenario ('mixed' included, where the valves switch), published the same way: a
recorded run of a design.

A cancelled goal stops waiting for its service calls at once, asks every worker to
stop the FMU run in progress (``/<worker>/cancel``), and ends with the best design of
the iterations completed.  A worker that failed a goal serves the next one if its
service is up again.  The loop
itself is :func:`suspension_tuning.tuning.optimise`, shared with in-process runs.
"""

from __future__ import annotations

import collections
import dataclasses
import math
import subprocess
import sys
import threading
import time
from typing import Any

import numpy as np
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
from suspension_tuning_interfaces.action import Optimise
from suspension_tuning_interfaces.msg import (
    CalibrationProgress,
    IterationRecord,
    OptimisationResult,
    TimeHistories,
)
from suspension_tuning_interfaces.srv import Calibrate, EvaluateGradient

from suspension_tuning.config_check import ConfigError, check_config
from suspension_tuning.evaluation import scenarios as evaluation_scenarios
from suspension_tuning.nodes._conditions import run_condition_goal
from suspension_tuning.nodes._parameters import declare_numbers, read_only
from suspension_tuning.nodes._pool import PoolEvent, pool_from_parameters
from suspension_tuning.nodes._services import ServiceCallError, call
from suspension_tuning.nodes._spin import run_node
from suspension_tuning.optim.correction import load_correction_options
from suspension_tuning.optim.dynamic_q import load_options
from suspension_tuning.optim.scaling import fit_note, load_min_fit_r2, poor_fits
from suspension_tuning.optim.simplified_gradient import run_calibration_samples
from suspension_tuning.paths import config_dir, dump_yaml, read_yaml
from suspension_tuning.physical_metrics import SHOWN, physical_metrics
from suspension_tuning.reported_design import design_success, reported_design, result_message
from suspension_tuning.tuning import (
    CONTINUED_FROM,
    INPUT_SCENARIOS,
    FullEvaluation,
    RunCancelled,
    RunCounter,
    TuningRequest,
    centre,
    optimise,
    physical_settings,
    with_noise_levels,
)
from suspension_tuning.vehicle.design import load_design_space, validate_design

CONFIG_DIR = config_dir()
#: Goal gradient_source of a single recorded full-model run instead of an optimisation.
EVALUATE = 'evaluate'
#: Latched: a late subscriber (the recorder) still gets the run's configuration/result.
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


def physical_units(n_vars: int) -> list[str]:
    """The unit of each physical name of an n-variable design (config/design_space.yaml)."""
    return list(load_design_space().physical_units(n_vars))


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


def ride_road_record(road: str) -> dict[str, Any]:
    """The run configuration's record of the ride road: the goal's, else the configured one.

    The road's name or file, and for a road file its path and SHA-256
    (:func:`suspension_tuning.vehicle.road.road_identity`); the workers' model
    fingerprint covers every file config/road.yaml names too.
    """
    from suspension_tuning.vehicle.params import load_scenarios_config
    from suspension_tuning.vehicle.road import road_identity

    source = 'goal' if road else 'config/scenarios.yaml ride.road'
    try:
        record = road_identity(road or str(load_scenarios_config()['ride']['road']))
    except ValueError as error:
        record = {'road': road, 'error': str(error)}
    return {'source': source, **record}


def record_to_msg(record: dict[str, Any], counter: RunCounter, t0: float) -> IterationRecord:
    """An optimiser history record as an IterationRecord message."""
    return IterationRecord(
        iteration=int(record['iteration']), x=np.asarray(record['x'], float).tolist(),
        f=float(record['f']), g=np.asarray(record['g'], float).tolist(),
        move_limit=float(record['rho']), move_limit_next=float(record['rho_next']),
        max_violation=float(record['max_violation']),
        n_full_runs=counter.full_runs, n_simplified_runs=counter.simplified_runs,
        wall_time_s=time.monotonic() - t0)


def action_result(result: Any, history: list[IterationRecord], t0: float,
                   counter: RunCounter) -> Optimise.Result:
    """The action result of a :func:`~suspension_tuning.tuning.optimise` result.

    x, f, g, the constraint values, the physical settings and the physical metrics
    (``metrics_best``, :mod:`suspension_tuning.physical_metrics`) are those of the
    reported design (:mod:`suspension_tuning.reported_design`): the best feasible
    iterate, or, when no iterate was feasible, the least violating one, which the
    message and ``feasible`` say plainly and which never counts as a success.  The last
    iterate is the history's last record.  The baseline's fields are the caller's.
    """
    design = reported_design(result)
    stop = str(result.message)
    if design is None:  # no point evaluated: the start point, unevaluated
        x = np.asarray(result.x, float).tolist()
        physical = physical_settings(x)
        return Optimise.Result(
            success=False, message=stop, x=x,
            constraint_gradient_sources=list(result.constraint_gradient_sources),
            physical_names=list(physical), physical_values=list(physical.values()),
            physical_units=physical_units(len(x)),
            iterations=int(result.get('nit', 0)), history=history,
            wall_time_s=time.monotonic() - t0, **counter.as_dict())
    physical = physical_settings(design.x)
    message = Optimise.Result(
        success=design_success(result, design),
        message=result_message(design, stop),
        x=design.x, f=design.f, g=design.g, feasible=design.feasible,
        best_iteration=design.iteration, max_violation=design.max_violation,
        constraint_values=design.constraint_values,
        constraint_gradient_sources=list(result.constraint_gradient_sources),
        physical_names=list(physical), physical_values=list(physical.values()),
        physical_units=physical_units(len(design.x)),
        iterations=int(result.nit), history=history, wall_time_s=time.monotonic() - t0,
        **counter.as_dict())
    scenario = str(result.get('scenario', ''))
    set_metrics(message, scenario, reported=physical_metrics(
        scenario, (), result.get('metrics_best') or {}))
    set_check(message, result)
    return message


def result_topic_message(result: Optimise.Result) -> OptimisationResult:
    """The action result as the message of ``/optimisation/result``, field for field.

    The topic has a message type of its own: an action's inner ``Optimise_Result`` is
    no message type that ``ros2 topic echo`` or Foxglove can resolve.  Bags recorded
    with that type stay readable (inspect_bag decodes with the definition in the bag).
    """
    return OptimisationResult(**{name: getattr(result, name)
                                 for name in OptimisationResult.get_fields_and_field_types()})


def set_check(message: Optimise.Result, result: Any, note: str = '') -> None:
    """The stop test and the tighter-tolerance check's verdicts (``tuning.optimise``)."""
    message.stop_test = str(result.get('stop_test', '') or '')
    check = result.get('check')
    message.check_max_violation = math.nan
    if not check:
        message.check = ''
        message.check_note = note or 'not checked at a tighter solver tolerance'
        return
    message.check = 'feasible' if check['feasible_check'] else 'infeasible'
    message.check_max_violation = float(check['max_violation_check'])
    message.check_note = check_note(check)


def check_note(check: dict[str, Any]) -> str:
    """Both verdicts of the check in words (``tuning.optimise``'s ``check``)."""
    first = check.get('first', check)
    text = (f"the run's model: {'feasible' if first['feasible_run'] else 'infeasible'}; "
            f"at the tighter tolerance: max g {first['max_violation_check']:.4g} "
            f"({'feasible' if first['feasible_check'] else 'infeasible'}, "
            f"tolerance {check.get('check_gtol', math.nan):.3g})")
    if check.get('continued') and check.get('continue_by') == 'tighter_model':
        text += (f"; continued on the tighter-tolerance model "
                 f"{CONTINUED_FROM.get(check.get('continued_from', ''), '')}: the "
                 f"answer's max g there {check['max_violation_check']:.4g} "
                 f"({'feasible' if check['feasible_check'] else 'infeasible'})")
        if not check['feasible_check']:
            text += '; no design feasible at the tighter tolerance was found'
    elif check.get('continued'):
        shift = ', '.join(f'{v:.4g}' for v in check.get('shift', []))
        text += (f"; continued {check['continuations']} time(s) with the tyre-hop "
                 f"constraints shifted by [{shift}]: the answer's max g at the tighter "
                 f"tolerance {check['max_violation_check']:.4g} "
                 f"({'feasible' if check['feasible_check'] else 'infeasible'})")
        if not check['feasible_check']:
            text += '; the solver tolerance decides this design\'s feasibility'
    elif check.get('not_continued') and first['feasible_run'] and not first['feasible_check']:
        text += (f"; {check['not_continued']}: the solver tolerance decides this design's "
                 'feasibility')
    if check.get('condition_max_g_check'):  # a condition set: where the check is tightest
        names = check.get('condition_names') or []
        worst = int(np.argmax(check['condition_max_g_check']))
        label = names[worst] if worst < len(names) else str(worst)
        text += (f"; largest g at the check in condition {label} "
                 f"({check['condition_max_g_check'][worst]:.4g})")
    return text


def set_metrics(message: Optimise.Result, scenario: str,
                reported: dict[str, float] | None = None,
                baseline: dict[str, float] | None = None) -> None:
    """Put the reported design's and/or the baseline's physical metrics into a result.

    ``metric_names`` lists every metric either side has, in the order of
    :data:`suspension_tuning.physical_metrics.SHOWN`; ``metrics`` and
    ``baseline_metrics`` hold one value per name (NaN where that side lacks it), or
    none when that side has no metrics at all.
    """
    sides = {'metrics': reported, 'baseline_metrics': baseline}
    for field, values in sides.items():
        if values is None:
            old = getattr(message, field)
            sides[field] = dict(zip(message.metric_names, old)) if len(old) else {}
    names = [shown for _, shown, _ in SHOWN.get(scenario, ())
             if any(shown in values for values in sides.values())]
    message.metric_names = names
    for field, values in sides.items():
        setattr(message, field, [float(values.get(n, math.nan)) for n in names]
                if values else [])


def config_first(text: str) -> str:
    """A goal's failure, led by the configuration's own line when a file is at fault.

    A worker that meets a configuration file it cannot use reports it inside its
    service error ("calibration failed: full-model samples failed: config/...");
    :func:`~suspension_tuning.config_check.check_config` on this host names the file
    and key first, the worker's text follows.
    """
    try:
        check_config(builtin_model=False)
    except ConfigError as error:
        return f'configuration: {error} ({text})'
    return text


class CoordinatorNode(Node):
    """Action server ``optimise`` over the simulation workers and gradient evaluator.

    Goals run one after another, in the order accepted (the queue of ros2/examples'
    ``server_queue_goals.py``): they share the workers, and a goal cancelled while
    it waits ends at its start, without a model run.  A goal's execute callback runs
    on a thread of the node's MultiThreadedExecutor and waits there for the service
    responses, which the clients' callback group takes on another thread; goal,
    cancel and result requests are answered meanwhile.
    """

    EXECUTOR = MultiThreadedExecutor

    def __init__(self, **kwargs) -> None:
        check_config(builtin_model=False)  # ConfigError: one line, before the node exists
        super().__init__('coordinator', **kwargs)
        self.declare_parameter('gradient_node', '/gradient_evaluator')
        # calibration_samples: eq. 25 samples per simplified scenario; -1 = each case's
        # default (config/simplified_models.yaml scaling.run_samples), 0 = none.
        declare_numbers(self, {'call_timeout_s': 600.0, 'calibration_samples': -1,
                               'fd_step': 0.025})
        self.declare_parameter('optimiser_config', '')
        self.declare_parameter('optimiser_section', 'vehicle')
        # One more full run at the reported design, publishing its telemetry for the bag; a
        # recording run, not part of the optimisation's run counts.
        self.declare_parameter('final_telemetry', True)
        # Seconds a goal's result is kept for late result requests after the goal ends
        # (rcl's default 900 s).  Every status message carries every goal kept, and an
        # action client converts all of them each time (config/graph.yaml).
        declare_numbers(self, {'result_timeout_s': 10.0})
        # Read once below; calibration_samples, fd_step and final_telemetry act when set.
        read_only(self, ['gradient_node', 'call_timeout_s', 'optimiser_config',
                         'optimiser_section', 'result_timeout_s'])
        self.timeout_s = float(self.get_parameter('call_timeout_s').value)
        self.stopping = False  # set by destroy_node: a running goal stops waiting
        clients = ReentrantCallbackGroup()
        self._running: Any = None  # the goal handle executing, if any
        # The goal whose workers were checked last, and when (time.monotonic()).
        self._pool_checked: tuple[Any, float] = (None, 0.0)
        # The workers found on the graph (nodes/_pool.py); a change of membership goes
        # out as the running goal's feedback.
        self.pool = pool_from_parameters(self, clients, self._stopped, self._on_pool_event)
        self._cancelling: Any = None  # the goal handle whose cancel was accepted
        gradient_node = str(self.get_parameter('gradient_node').value).rstrip('/')
        self.gradient_client = self.create_client(EvaluateGradient, f'{gradient_node}/gradient',
                                                  callback_group=clients)
        self.calibrate_client = self.create_client(Calibrate, f'{gradient_node}/calibrate',
                                                   callback_group=clients)
        # A calibration's progress, passed on as the calibrating goal's feedback.
        # (goal handle, scenario, n_vars) of the calibration under way.
        self._calibrating: tuple[Any, str, int] | None = None
        self.create_subscription(CalibrationProgress, f'{gradient_node}/calibration_progress',
                                 self._on_calibration_progress, 100, callback_group=clients)
        config = str(self.get_parameter('optimiser_config').value) or str(
            CONFIG_DIR / 'optimiser.yaml')
        self.options = load_options(config, str(self.get_parameter('optimiser_section').value))
        self.correction = load_correction_options(config)
        self.min_fit_r2 = load_min_fit_r2(config)
        #: The baseline design's run per (scenario, n_vars, integrator, road, model
        #: fingerprint): (x, f, metric names, metrics).
        self._baselines: dict[tuple[str, int, str, str, str],
                              tuple[list[float], float, list[str], list[float]]] = {}
        self.progress_pub = self.create_publisher(IterationRecord, '/optimisation/progress',
                                                  RELIABLE)
        self.config_pub = self.create_publisher(String, '/optimisation/run_config', LATCHED)
        self.result_pub = self.create_publisher(OptimisationResult, '/optimisation/result',
                                                LATCHED)
        # Dumped once (29 ms): the configuration files do not change while the node runs.
        self.static_config_yaml = configuration_yaml()
        self._queue: collections.deque = collections.deque()
        self._idle = threading.Condition()
        self.server = ActionServer(
            self, Optimise, '~/optimise', execute_callback=self._execute,
            goal_callback=lambda _: GoalResponse.ACCEPT,
            handle_accepted_callback=self._on_accepted,
            cancel_callback=self._on_cancel,
            callback_group=ReentrantCallbackGroup(),
            result_timeout=float(self.get_parameter('result_timeout_s').value))

    def _on_accepted(self, goal_handle) -> None:
        """Execute the goal now, or after the goals accepted before it."""
        with self._idle:
            if self._running is None:
                self._running = goal_handle
                goal_handle.execute()
            else:
                self._queue.append(goal_handle)

    def _on_cancel(self, goal_handle) -> CancelResponse:
        """Accept; for the running goal, stop the workers' FMU runs in progress too."""
        if goal_handle is self._running:
            self._cancelling = goal_handle
            self.pool.cancel_runs()  # the workers' FMU runs in progress; the goal ends anyway
        return CancelResponse.ACCEPT

    def _on_pool_event(self, event: PoolEvent) -> None:
        """A worker lost, joined, back or refused: the running goal's feedback says so.

        Workers found while the goal starts (:meth:`SimulationPool.check_models`) are
        the goal's own, recorded in its run configuration: a join is news only after.
        """
        running = self._running
        if running is None or not running.is_active:
            return
        checked, at = self._pool_checked
        if event.kind == 'joined' and (checked is not running or event.time_s <= at):
            return
        running.publish_feedback(Optimise.Feedback(phase='pool', note=event.text))

    def _check_pool(self, goal_handle) -> str:
        """The workers' one model for ``goal_handle`` (SimulationPool.check_models).

        Workers that joined until now are the goal's own (:meth:`_on_pool_event`).
        """
        fingerprint = self.pool.check_models()
        self._pool_checked = (goal_handle, time.monotonic())
        return fingerprint

    def _cancel_requested(self) -> bool:
        running = self._running
        return running is not None and (running is self._cancelling
                                        or running.is_cancel_requested)

    def _next_goal(self) -> None:
        """Start the next queued goal (at the end of a goal's execute callback)."""
        with self._idle:
            self._running = self._queue.popleft() if self._queue and not self.stopping else None
            if self._running is not None:
                self._running.execute()
            self._idle.notify_all()

    # ------------------------------------------------------------------ helpers
    def _request(self, goal: Optimise.Goal) -> TuningRequest:
        options = self.options.as_dict()
        if goal.max_iterations:
            # the goal's limit is the limit, whatever the number of variables
            options['maxiter'] = int(goal.max_iterations)
            options['maxiter_variables'] = 0
        if goal.move_limit:
            options['rho0'] = float(goal.move_limit)
        constraints = [(c.scenario, c.quantity, c.upper_bound) for c in goal.constraints]
        return TuningRequest(goal.scenario, int(goal.n_vars), list(goal.x0) or None,
                             goal.gradient_source or 'simplified', options,
                             float(self.get_parameter('fd_step').value), constraints,
                             integrator=goal.integrator, correction=self.correction,
                             road=goal.road, conditions=goal.conditions,
                             condition_form=goal.condition_form)

    def _publish_run_config(self, request: TuningRequest) -> None:
        config = {
            'scenario': request.scenario, 'n_vars': request.n_vars,
            'x0': request.start.tolist(), 'gradient_source': request.gradient_source,
            'optimiser_options': request.options, 'fd_step': request.fd_step,
            'gradient_correction': dict(request.correction or {}),
            'constraints': [c.as_dict() for c in request.constraints],
            'constraint_gradient_sources': request.constraint_gradient_sources(),
            'integrator': request.integrator or 'simulation default',
            'coordinator_parameters': {name: p.value for name, p in
                                       self.get_parameters_by_prefix('').items()},
            'calibration_fit': {'min_r2': self.min_fit_r2},
            'model_fingerprint': self.pool.fingerprint,
            'simulation_models': self._worker_models(),
            'ride_road': ride_road_record(request.road),
        }
        if request.condition_set is not None:
            config.update(conditions=request.condition_set.as_dict(),
                          condition_form=request.condition_form)
        stamp = f'started_unix_s: {time.time()!r}\n'
        self.config_pub.publish(String(data=dump_yaml(config) + stamp + self.static_config_yaml))

    def _worker_models(self) -> dict[str, Any]:
        """Each worker's model description (after :meth:`SimulationPool.check_models`)."""
        models = self.pool.models
        return {name: models.get(name, 'no model description received')
                for name in sorted({*models, *self.pool.allow})}

    def _full_model(self, request: TuningRequest, scenario: str | None = None):
        """The full model of ``scenario`` (default the objective's) on the workers."""
        scenario = scenario or request.scenario

        def evaluate(designs: np.ndarray) -> FullEvaluation:
            # The simplified handling model (of 'handling' and 'mixed') runs on the
            # inputs of the full run at x (simplified_inputs.py); the ride model needs none.
            try:
                responses = self.pool.evaluate(
                    scenario, request.n_vars, designs,
                    return_inputs=(request.gradient_source == 'simplified'
                                   and len(designs) == 1 and scenario in INPUT_SCENARIOS),
                    integrator=request.integrator, road=request.road)
            except (ValueError, ServiceCallError) as error:
                if self._cancel_requested():
                    raise RunCancelled(str(error)) from error
                raise
            f = np.concatenate([np.asarray(r.f, float) for r in responses])
            g = np.concatenate([np.asarray(r.g, float).reshape(r.n_designs, r.n_constraints)
                                for r in responses])
            metrics = np.concatenate([np.asarray(r.metrics, float).reshape(
                r.n_designs, len(r.metric_names)) for r in responses])
            inputs = responses[0].inputs[0] if responses[0].inputs else None
            return FullEvaluation(f=f, g=g, inputs=inputs,
                                  metric_names=list(responses[0].metric_names),
                                  metrics=metrics)
        return evaluate

    def _baseline(self, request: TuningRequest, fingerprint: str
                  ) -> tuple[list[float], float, list[str], list[float]]:
        """The baseline design's run (config/design_space.yaml): x, f, metric names, metrics.

        One full run of the objective's scenario on the workers, kept for the next goal
        of the same scenario, variables, integrator, road and model.
        """
        key = (request.scenario, request.n_vars, request.integrator, request.road, fingerprint)
        if key not in self._baselines:
            x = load_design_space().baseline_x(request.n_vars)
            [response] = self.pool.evaluate(request.scenario, request.n_vars, x[None, :],
                                            integrator=request.integrator, road=request.road)
            self._baselines[key] = (x.tolist(), float(response.f[0]),
                                    list(response.metric_names), list(response.metrics))
        return self._baselines[key]

    def _add_baseline(self, message: Optimise.Result, request: TuningRequest,
                      fingerprint: str) -> None:
        """The baseline design's fields of the result (a failed run: a warning)."""
        try:
            x, f, names, values = self._baseline(request, fingerprint)
        except (ValueError, ServiceCallError) as error:
            self.get_logger().warning(f'run of the baseline design failed: {error}')
            return
        message.baseline_x, message.baseline_f = x, f
        message.baseline_physical_values = list(physical_settings(x).values())
        set_metrics(message, request.scenario, baseline=physical_metrics(
            request.scenario, names, values))

    def _simplified_gradient(self, request: TuningRequest, scenario: str | None = None):
        """The scaled simplified gradient of ``scenario`` from the gradient evaluator."""
        scenario = scenario or request.scenario

        def gradient(x: np.ndarray, inputs: Any
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
            try:
                response = call(self, self.gradient_client, EvaluateGradient.Request(
                    scenario=scenario, n_vars=request.n_vars, x=x.tolist(),
                    step=request.fd_step, road=request.road,
                    inputs=TimeHistories() if inputs is None else inputs), self.timeout_s,
                    self._stopped)
            except ServiceCallError as error:
                if self._cancel_requested():
                    raise RunCancelled(str(error)) from error
                raise
            if not response.success:
                raise ValueError(f'gradient evaluator: {response.error}')
            dg = np.asarray(response.dg, float).reshape(response.n_constraints, request.n_vars)
            values = np.asarray(response.values, float) if len(response.values) else None
            return np.asarray(response.df, float), dg, values
        return gradient

    @staticmethod
    def _simplified_scenarios(request: TuningRequest) -> list[str]:
        """The objective's scenario and every other one with simplified-gradient terms."""
        names = [request.scenario] + [
            c.scenario for c, source in zip(request.constraints,
                                            request.constraint_gradient_sources())
            if source == 'simplified']
        return list(dict.fromkeys(names))

    def _calibrate(self, goal_handle, request: TuningRequest, scenario: str | None = None
                   ) -> Calibrate.Response:
        scenario = scenario or request.scenario
        samples = run_calibration_samples(
            scenario, request.n_vars, int(self.get_parameter('calibration_samples').value))
        self._calibrating = (goal_handle, scenario, request.n_vars)
        try:
            response = call(self, self.calibrate_client, Calibrate.Request(
                scenario=scenario, n_vars=request.n_vars, n_samples=samples,
                unit_scaling=samples == 0, force=False,
                integrator=request.integrator, model_fingerprint=self.pool.fingerprint,
                road=request.road),
                self.timeout_s * 2, self._stopped)
        finally:
            self._calibrating = None
        if not response.success:
            raise ValueError(f'calibration failed: {response.error}')
        return response

    def _check_fit(self, goal_handle, request: TuningRequest, scenario: str,
                   response: Calibrate.Response) -> None:
        """Feedback and log the calibration's fit; refuse one below the threshold.

        Without samples (unit scaling) there is no fit to judge: the feedback says so.
        """
        if not len(response.function_names):
            note = (f'{scenario}/{request.n_vars}: no eq. 25 calibration (0 full-model '
                    'samples; unit scaling, corrected along the run from its own full '
                    'runs; coordinator calibration_samples, default config/'
                    'simplified_models.yaml scaling.run_samples)')
            goal_handle.publish_feedback(Optimise.Feedback(phase='calibration_fit',
                                                           note=note))
            self.get_logger().info(note)
            return
        note = fit_note(scenario, request.n_vars, response.function_names,
                        response.r_squared, response.full_max, self.min_fit_r2)
        goal_handle.publish_feedback(Optimise.Feedback(phase='calibration_fit', note=note))
        self.get_logger().info(note)
        poor = poor_fits(response.function_names, response.r_squared, response.full_max,
                         self.min_fit_r2)
        if poor:
            fits = ', '.join(f'{name} {r2:.2f}' for name, r2 in poor)
            raise ValueError(
                f'the simplified {scenario} model does not fit this full model (model '
                f'{self.pool.fingerprint}): eq. 25 R^2 {fits}, below the threshold '
                f'{self.min_fit_r2:g} (config/optimiser.yaml calibration_fit.min_r2); its '
                'gradients would mislead Dynamic-Q.  Use full-model gradients (tune '
                '--gradient full; goal gradient_source full), or lower min_r2 to run on the '
                'corrected simplified gradients anyway')

    def _on_calibration_progress(self, msg: CalibrationProgress) -> None:
        calibrating = self._calibrating
        if calibrating is not None and (msg.scenario, msg.n_vars) == calibrating[1:]:
            calibrating[0].publish_feedback(Optimise.Feedback(phase='calibration',
                                                              calibration=msg))

    # ------------------------------------------------------------------ action
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
            if self.context.ok() and not self.stopping:
                raise  # rclpy logs it and aborts the goal
            return Optimise.Result(success=False, message='stopped: ROS shut down under the '
                                   f'goal ({type(error).__name__}: {error})')
        finally:
            self._next_goal()

    def _evaluate_run(self, goal_handle, t0: float) -> Optimise.Result:
        """One full-model run of the goal's x0 as a recorded run (gradient_source 'evaluate').

        Any full-model scenario, 'mixed' included (the valves switch only there): the
        run configuration, one progress record (f, g and the largest violation), the
        run's telemetry and the result are published as for an optimisation, so the
        recorder puts the run in a bag of its own.
        """
        goal = goal_handle.request
        try:
            if goal.scenario not in evaluation_scenarios():
                raise ValueError(f'unknown scenario {goal.scenario!r}; valid: '
                                 f'{", ".join(evaluation_scenarios())}')
            n_vars = int(goal.n_vars)
            x = validate_design(list(goal.x0) or centre(n_vars), n_vars)[0]
            if goal.road:
                TuningRequest('ride', n_vars, x, road=goal.road)  # the road's checks
        except ValueError as error:
            goal_handle.abort()
            return Optimise.Result(success=False, message=f'bad goal: {error}')
        try:
            fingerprint = self._check_pool(goal_handle)
            refusal = None
        except (ValueError, ServiceCallError) as error:
            fingerprint, refusal = '', error
        config = {'scenario': goal.scenario, 'n_vars': n_vars, 'x0': x.tolist(),
                  'gradient_source': 'evaluate', 'kind': 'evaluation (one full-model run)',
                  'integrator': goal.integrator or 'simulation default',
                  'model_fingerprint': self.pool.fingerprint,
                  'simulation_models': self._worker_models(),
                  'ride_road': ride_road_record(goal.road)}
        stamp = f'started_unix_s: {time.time()!r}\n'
        self.config_pub.publish(String(data=dump_yaml(config) + stamp + self.static_config_yaml))
        try:
            if refusal is not None:
                raise refusal
            response = self.pool.evaluate(goal.scenario, n_vars, x[None, :],
                                          publish_telemetry=True, integrator=goal.integrator,
                                          road=goal.road)[0]
        except (ValueError, ServiceCallError) as error:
            text = config_first(f'evaluation failed: {error}')
            self.get_logger().error(text)
            goal_handle.abort()
            message = Optimise.Result(success=False, message=text,
                                      model_fingerprint=fingerprint,
                                      wall_time_s=time.monotonic() - t0)
            self.result_pub.publish(result_topic_message(message))
            return message
        g = np.asarray(response.g, float)
        violation = float(max(0.0, g.max())) if g.size else 0.0
        counter = RunCounter()
        counter.full_runs = 1
        record = record_to_msg({'iteration': 0, 'x': x, 'f': response.f[0], 'g': g, 'rho': 0.0,
                                'rho_next': 0.0, 'max_violation': violation}, counter, t0)
        goal_handle.publish_feedback(Optimise.Feedback(phase='iteration', latest=record))
        self.progress_pub.publish(record)
        physical = physical_settings(x)
        message = Optimise.Result(
            success=True, message='evaluated: one full-model run of x0, no optimisation',
            x=x.tolist(), f=float(response.f[0]), g=g.tolist(),
            feasible=violation <= self.options.gtol, best_iteration=0,
            max_violation=violation, physical_names=list(physical),
            physical_values=list(physical.values()), physical_units=physical_units(len(x)),
            iterations=0, history=[record],
            wall_time_s=time.monotonic() - t0, model_fingerprint=fingerprint,
            **counter.as_dict())
        set_metrics(message, goal.scenario, reported=physical_metrics(
            goal.scenario, response.metric_names, response.metrics))
        goal_handle.succeed()
        self.result_pub.publish(result_topic_message(message))
        return message

    def _optimise(self, goal_handle) -> Optimise.Result:
        t0 = time.monotonic()
        try:  # a file edited since the start: its own line, before any worker fails on it
            check_config(builtin_model=False)
        except ConfigError as error:
            self.get_logger().error(f'goal refused: {error}')
            goal_handle.abort()
            message = Optimise.Result(success=False, message=f'configuration: {error}')
            self.result_pub.publish(result_topic_message(message))
            return message
        if goal_handle.request.gradient_source == EVALUATE:
            return self._evaluate_run(goal_handle, t0)
        try:
            request = self._request(goal_handle.request)
        except ValueError as error:
            goal_handle.abort()
            return Optimise.Result(success=False, message=f'bad goal: {error}')
        if goal_handle.is_cancel_requested:  # cancelled while it waited for an earlier goal
            goal_handle.canceled()
            return Optimise.Result(success=False, message='cancelled before it started')
        refusal = None
        try:
            fingerprint = self._check_pool(goal_handle)
        except (ValueError, ServiceCallError) as error:
            refusal = error
        # The run configuration records every worker's model, also for a refused goal.
        self._publish_run_config(request)
        if refusal is not None:
            self.get_logger().error(f'optimisation refused: {refusal}')
            goal_handle.abort()
            message = Optimise.Result(success=False, message=f'refused: {refusal}')
            self.result_pub.publish(result_topic_message(message))
            return message
        if request.condition_set is not None:
            return run_condition_goal(self, goal_handle, request, fingerprint, t0,
                                      sys.modules[__name__])
        self.get_logger().info(f'optimising {request.scenario} with {request.n_vars} '
                               f'variables, {request.gradient_source} gradients, model '
                               f'{fingerprint}')
        counter = RunCounter()
        history_msgs: list[IterationRecord] = []

        def on_iteration(record: dict[str, Any], counts: RunCounter) -> bool:
            msg = record_to_msg(record, counts, t0)
            history_msgs.append(msg)
            goal_handle.publish_feedback(Optimise.Feedback(phase='iteration', latest=msg))
            self.progress_pub.publish(msg)
            return goal_handle.is_cancel_requested

        try:
            gradients = {}
            if request.gradient_source == 'simplified':
                for scenario in self._simplified_scenarios(request):
                    calibration = self._calibrate(goal_handle, request, scenario)
                    counter.calibration_runs += int(calibration.n_full_runs)
                    self._check_fit(goal_handle, request, scenario, calibration)
                    gradients[scenario] = self._simplified_gradient(request, scenario)
            models = {name: self._full_model(request, name)
                      for name in request.constraint_scenarios}
            checking, note = self._check_options(request, fingerprint)
            if checking['check_model'] is not None:  # the built-in model: its noise levels
                request = dataclasses.replace(request, options=with_noise_levels(
                    request.options, request.scenario, request.integrator))
            result = optimise(request, self._full_model(request),
                              self._simplified_gradient(request), on_iteration,
                              counter=counter, constraint_models=models,
                              constraint_gradients=gradients, **checking)
        except (ValueError, ServiceCallError) as error:
            if self._cancel_requested():  # e.g. during the calibration
                self.get_logger().info(f'goal cancelled ({error})')
                goal_handle.canceled()
                text = 'cancelled'
            else:
                text = str(error) if self.stopping else config_first(str(error))
                self.get_logger().error(f'optimisation failed: {text}')
                goal_handle.abort()
            message = Optimise.Result(success=False, message=text, history=history_msgs,
                                      wall_time_s=time.monotonic() - t0,
                                      model_fingerprint=fingerprint, **counter.as_dict())
            self.result_pub.publish(result_topic_message(message))
            return message
        message = action_result(result, history_msgs, t0, counter)
        if not result.get('check'):
            message.check_note = note
        message.model_fingerprint = fingerprint
        design = reported_design(result)
        if design is not None and not goal_handle.is_cancel_requested:
            self._add_baseline(message, request, fingerprint)
        if (design is not None and self.get_parameter('final_telemetry').value
                and not goal_handle.is_cancel_requested):
            try:
                [response] = self.pool.evaluate(request.scenario, request.n_vars,
                                                np.asarray(design.x, float)[None, :],
                                                publish_telemetry=True,
                                                integrator=request.integrator,
                                                road=request.road)
                if not len(message.metrics):  # a resumed design without recorded metrics
                    set_metrics(message, request.scenario, reported=physical_metrics(
                        request.scenario, response.metric_names, response.metrics))
            except (ValueError, ServiceCallError) as error:
                self.get_logger().warning(f'telemetry run of the reported design failed: '
                                          f'{error}')
        message.wall_time_s = time.monotonic() - t0
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
            message.message = 'cancelled' if design is None else f'cancelled; {design.statement}'
        else:
            goal_handle.succeed()
        self.result_pub.publish(result_topic_message(message))
        return message

    def _check_options(self, request: TuningRequest, fingerprint: str
                       ) -> tuple[dict[str, Any], str]:
        """``optimise``'s check arguments: the built-in model at the tighter tolerance, in
        this process, or none and why.

        The workers' model must be the built-in one on the configured road (an FMU's
        tolerance would go through FMI's setupExperiment, which the workers do not
        take per goal).  Returns (arguments, note).
        """  # noqa: D205
        from suspension_tuning import simplified_inputs
        from suspension_tuning.answer_check import check_options
        from suspension_tuning.model_identity import builtin_fingerprint
        from suspension_tuning.vehicle.params import INTEGRATORS
        from suspension_tuning.vehicle.simplified import SimplifiedInputs

        def packed(result: Any) -> TimeHistories:  # as the simulation node returns them
            return simplified_inputs.pack(SimplifiedInputs.from_scenario_result(result, 0),
                                          TimeHistories())

        none = {'check_model': None, 'check_gtol': 5e-3, 'check_continuations': 0}
        try:
            options = check_options(request.scenario, request.n_vars, inputs=packed)
        except (ValueError, KeyError, OSError) as error:
            return none, f'not checked: {error}'
        if request.road:
            return none, 'not checked: a goal road (the check runs the configured road)'
        # the workers' fingerprint is that of their default integrator; a goal may ask
        # for either (EvaluateDesign.integrator), so the built-in model is any of them
        if fingerprint not in {builtin_fingerprint(name) for name in INTEGRATORS}:
            return none, ("not checked: the workers' model is not the built-in one (an FMU "
                          "is checked only where its setupExperiment tolerance can be set, "
                          "which the workers do not do per goal)")
        return options, ''

    def _stopped(self) -> bool:
        """Stop waiting for services: the node shuts down, or the goal is cancelled."""
        return self.stopping or self._cancel_requested()

    def destroy_node(self) -> None:
        """Let a running goal end, drop the queued ones, destroy the action server too.

        A running goal's service waits end within a second (10 s at most).  rclpy's
        ``Node.destroy_node`` leaves action servers alone: the server's handles keep the
        node's DDS participant alive, and other processes go on seeing an ``optimise``
        action that never answers.
        """
        with self._idle:
            self.stopping = True
            self._idle.wait_for(lambda: self._running is None, 10.0)
        self.server.destroy()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run suspension_tuning coordinator``."""
    run_node(CoordinatorNode, args, name='coordinator')


if __name__ == '__main__':
    main()
