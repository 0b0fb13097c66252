"""ROS 2 node ``full_vehicle_sim``: the full nonlinear vehicle model as a service.

Service ``~/evaluate`` (EvaluateDesign): a scenario and one or many designs in; the
objective f (eq. 9 or 10), the tyre-hop constraints g (eq. 11), named metrics, the
simplified models' inputs of each design and the wall time out.  A bad request
(unknown scenario, wrong length, NaN, out of bounds, more designs than parameter
``max_designs_per_request``, default 128) gets ``success = false`` and the reason in
``error``, at once and without a run; the node keeps serving.  A request with no
scenario and no designs is a ping: ``success = true``, no designs, the model's
fingerprint (a pool sends one before a worker's first piece).  A request's ``road``
drives the ride and mixed scenarios on another road than config/scenarios.yaml's (a road of
config/road.yaml, a road file or an entry, :func:`suspension_tuning.vehicle.road.
resolve_road`); a bad or too short road file is such a bad request.

On request it publishes the time histories of the first design as telemetry on
standard types, stamped with simulated time (:mod:`suspension_tuning.telemetry` has
the table): ``~/telemetry/imu`` (sensor_msgs/Imu: the body's attitude, rates and
longitudinal, lateral and vertical acceleration), ``~/telemetry/attitude``
(geometry_msgs/Vector3Stamped: roll, pitch and yaw angles, rad),
``~/telemetry/seat/{driver,passenger}``
and ``~/telemetry/seat/{driver,passenger}_wb`` (geometry_msgs/AccelStamped: each
seat's vertical acceleration, unweighted and BS 6841 W_b weighted),
``~/telemetry/struts`` (JointState: stroke m, force N per strut),
``~/telemetry/tyres`` (JointState: slip angle rad, normal force N) and
``~/telemetry/steering`` (JointState: front road-wheel angle and rate).

Scenario ``mixed`` runs closed-loop against the valve controller on simulated time:
for each control period the node publishes ``/clock`` and ``/vehicle/state`` (step k)
and waits for ``/suspension/valve_state`` answering step k before it integrates on,
so the run is step-locked and deterministic (parameter ``valve_controller``: 'ros',
or 'inprocess' for the same controller without topics).

Several workers run as ``--ros-args -r __node:=sim_0`` etc.; each serves its own
``/<name>/evaluate``.  A worker started on its own whose process was paused for more than
10 s (stopped, its host suspended) makes its node again as a new DDS participant, so
that the pools find it again (:mod:`suspension_tuning.nodes._pause`).

Parameter ``model``: 'builtin' (default) or 'fmu', a user's full vehicle model as an
FMI co-simulation FMU (``fmu_path``, ``fmu_mapping``: docs/fmu.md), checked at
start-up: a worker whose FMU or mapping does not fit does not start.  ``~/model``
(std_msgs/String, latched) says which model the worker runs (for an FMU: its file,
GUID or instantiation token and the mapping) with its fingerprint
(:mod:`suspension_tuning.model_identity`), which every answer carries too and the
start-up log names in one line; the coordinator records it in the run configuration
and leaves out workers whose fingerprints differ from the pool's.  ``~/model``'s
writer asserts its liveliness every ``liveliness_lease_s`` (s, DDS automatic
liveliness): the coordinator and the gradient evaluator find the worker on the graph
by its ``~/evaluate`` service and hear within their ``worker_loss_timeout_s`` when its
process or host is gone (:mod:`suspension_tuning.nodes._pool`).  An FMU worker publishes no
telemetry.

An FMU runs each design in a child process (``fmu_isolation`` 'process', the default;
``fmu_processes`` of them, :mod:`suspension_tuning.fmu.isolated`): a crash, an exit, a
hang longer than ``fmu_timeout_s`` (s) or NaN outputs fail that design's request with
an error naming the design, the simulation time reached and the cause, and the worker
serves on.  The FMU's own log messages go to the worker's log.  Service ``~/cancel``
(std_srvs/Trigger) stops the FMU run in progress (the coordinator calls it when its
goal is cancelled); its request then fails as cancelled.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String
from std_srvs.srv import Trigger
from suspension_tuning_interfaces.msg import TimeHistories, ValveState, VehicleState
from suspension_tuning_interfaces.srv import EvaluateDesign

from suspension_tuning import evaluation, simplified_inputs, telemetry
from suspension_tuning.config_check import ConfigError, check_config
from suspension_tuning.fmu import FmuConfigError, MappingError, worker_model
from suspension_tuning.fmu.fmi_log import FmuMessage
from suspension_tuning.fmu.isolated import DEFAULT_TIMEOUT_S, FmuRunCancelledError
from suspension_tuning.model_identity import builtin_description, summary_line
from suspension_tuning.nodes._parameters import ParameterError, declare_numbers, read_only
from suspension_tuning.nodes._pause import PauseWatch
from suspension_tuning.nodes._pool import model_qos
from suspension_tuning.nodes._services import serve
from suspension_tuning.nodes._spin import run_node
from suspension_tuning.paths import dump_yaml
from suspension_tuning.telemetry import stamp, telemetry_messages
from suspension_tuning.vehicle.params import load_vehicle_params
from suspension_tuning.vehicle.simplified import SimplifiedInputs

#: Vehicle states and valve states must not be dropped in a step-locked run.
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
#: Telemetry of a run is published as one burst after the simulation (thousands of
#: samples within a second), not at sensor rate: a reliable writer deep enough for a
#: whole run keeps every sample for the recorder; best-effort subscribers (plot tools)
#: are compatible with it.
TELEMETRY = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)
#: Designs one ~/evaluate request may hold (parameter ``max_designs_per_request``): above
#: every batch the graph sends (pieces of a batch: at most the eq. 25 calibration's 16
#: samples, paper 30; full-model gradients: 2n + 1 <= 9), far below a request that
#: would hold a worker for minutes after its caller gave up (a ride design takes ~0.05 s
#: here: 5,000 take 4 minutes).
MAX_DESIGNS_PER_REQUEST = 128

#: Wall-clock time the FMU start-up plausibility check may take in all, s (parameter
#: ``plausibility_timeout_s``; runs in child processes): the bound on the time a worker
#: is unreachable at start because of it (docs/fmu.md).  An estimate: an FMU whose
#: centre runs take longer gets its check cut short with a warning naming the
#: parameter, and serves all the same (raise it for a slow FMU).
PLAUSIBILITY_TIMEOUT_S = 120.0


class ValveLink:
    """The sim's end of the closed loop: ``/suspension/valve_state``, taken by the run.

    A hidden node of its own (``_<name>_valve_link``, no parameters, no rosout) holds the
    valve-state subscription, and an executor of its own that only the thread running
    the mixed scenario spins while it waits for step k's answer: the answer is taken
    and handed over on that thread, without the node's multi-threaded executor.  (A
    subscription of the sim node itself is served on another thread of its pool; every
    hand-over then waits for the GIL held by the integrating thread while the
    executor's own thread keeps waking: measured, a 2-variable ride-length mixed run
    took minutes instead of seconds.)  The topic is resolved by the sim node, so its
    remappings apply; the link node takes no command-line arguments of its own (a
    ``__node`` remap would give it the sim's name).
    """

    def __init__(self, node: Node) -> None:
        topic = node.resolve_topic_name('/suspension/valve_state')
        self.node = Node(f'_{node.get_name()}_valve_link', namespace=node.get_namespace(),
                         context=node.context, use_global_arguments=False,
                         enable_rosout=False, start_parameter_services=False)
        self.answers: dict[int, tuple[int, int, int, int]] = {}
        self.node.create_subscription(ValveState, topic, self._on_valve_state, RELIABLE)
        self.executor = SingleThreadedExecutor(context=node.context)
        self.executor.add_node(self.node)

    def _on_valve_state(self, msg: ValveState) -> None:
        self.answers[int(msg.step)] = (msg.front_spring, msg.front_damping,
                                       msg.rear_spring, msg.rear_damping)

    def wait_for(self, step: int, timeout_s: float) -> tuple[int, int, int, int] | None:
        """The valve state answering ``step``, or None after ``timeout_s`` (s)."""
        deadline = time.monotonic() + timeout_s
        while step not in self.answers:
            left = deadline - time.monotonic()
            if left <= 0.0 or not self.node.context.ok():
                return None
            self.executor.spin_once(timeout_sec=left)
        return self.answers[step]

    def destroy(self) -> None:
        """Remove the link node from the graph."""
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()


class TopicValveController:
    """A mixed-scenario valve controller reached over topics, step-locked.

    Each call publishes ``/clock`` and the vehicle state of step k, then waits until the
    valve controller node answers step k on ``/suspension/valve_state``.
    """

    def __init__(self, node: FullVehicleSimNode, timeout_s: float) -> None:
        self.node = node
        self.timeout_s = timeout_s

    def __call__(self, step: int, state: dict) -> tuple[int, int, int, int]:
        """Publish step ``step``'s state and return the valve state answering it."""
        node = self.node
        sim_time = stamp(state['t_s'])
        node.clock_pub.publish(Clock(clock=sim_time))
        msg = VehicleState(step=step, speed_mps=state['speed_mps'],
                           lateral_acceleration_mps2=state['lateral_acceleration_mps2'],
                           roll_angle_rad=state['roll_angle_rad'],
                           roll_rate_radps=state['roll_rate_radps'],
                           steering_angle_rad=state['steering_angle_rad'],
                           steering_rate_radps=state['steering_rate_radps'],
                           strut_pressure_pa=list(state['strut_pressure_pa']))
        msg.header.stamp, msg.header.frame_id = sim_time, 'base_link'
        # A state without an answer within a second is published again (the
        # controller's update is idempotent for a repeated step).
        deadline = time.monotonic() + self.timeout_s
        node.valve_link.answers.clear()
        while True:
            node.state_pub.publish(msg)
            answer = node.valve_link.wait_for(step, min(1.0, deadline - time.monotonic()))
            if answer is not None:
                return answer
            if not node.context.ok():
                raise RuntimeError(f'the node shut down while waiting for the valve state '
                                   f'of step {step}')
            if time.monotonic() >= deadline:
                raise RuntimeError(f'no valve state for step {step} within '
                                   f'{self.timeout_s} s: is the valve_controller node '
                                   'running?')
            node.get_logger().warning(f'no valve state for step {step} yet: '
                                      'publishing the vehicle state again')


class FullVehicleSimNode(Node):
    """Service adapter over :func:`suspension_tuning.evaluation.evaluate`.

    Multi-threaded: ``~/cancel`` is served while an evaluate request runs.  A
    closed-loop run takes its valve states on its own thread (:class:`ValveLink`).
    """

    EXECUTOR = MultiThreadedExecutor

    def __init__(self, name: str = 'full_vehicle_sim', **kwargs) -> None:
        super().__init__(name, **kwargs)
        self.declare_parameter('valve_controller', 'ros')
        self.declare_parameter('model', 'builtin')
        self.declare_parameter('fmu_path', '')
        self.declare_parameter('fmu_mapping', '')
        # FMU start-up check with one run (auto: when the FMU declares no unit for a
        # mapped variable; always; never), docs/fmu.md
        self.declare_parameter('plausibility_check', 'auto')
        self.declare_parameter('fmu_isolation', 'process')
        try:  # the configuration files, before they are used (ConfigError: one line)
            check_config(builtin_model=str(self.get_parameter('model').value) == 'builtin')
        except ConfigError:
            Node.destroy_node(self)
            raise
        # full-model integrator when a request names none (config/vehicle.yaml default)
        self.declare_parameter('integrator', load_vehicle_params().integrator.method)
        try:  # before anything else: a bad FMU set-up leaves nothing half-started
            declare_numbers(self, {'telemetry_decimation': 2, 'closed_loop_timeout_s': 5.0,
                                   'fmu_timeout_s': DEFAULT_TIMEOUT_S, 'fmu_processes': 1,
                                   'plausibility_timeout_s': PLAUSIBILITY_TIMEOUT_S,
                                   'liveliness_lease_s': 0.5,
                                   'max_designs_per_request': MAX_DESIGNS_PER_REQUEST,
                                   'telemetry_rate': 0.0})
            # Read once at start-up (the model, its fingerprint, the liveliness QoS).
            read_only(self, ['model', 'fmu_path', 'fmu_mapping', 'plausibility_check',
                             'fmu_isolation', 'integrator', 'fmu_timeout_s', 'fmu_processes',
                             'plausibility_timeout_s', 'liveliness_lease_s'])
            param = self.get_parameter
            self.fmu = worker_model(
                *(str(param(name).value) for name in ('model', 'fmu_path', 'fmu_mapping')),
                isolation=str(param('fmu_isolation').value),
                timeout_s=param('fmu_timeout_s').value, processes=param('fmu_processes').value,
                on_message=self._on_fmu_message, stopping=lambda: not self.context.ok())
        except (FmuConfigError, MappingError, ParameterError):
            Node.destroy_node(self)
            raise
        self.model_description = (
            builtin_description(str(self.get_parameter('integrator').value))
            if self.fmu is None else self.fmu.description())
        self.model_fingerprint = self.model_description['fingerprint']
        self.get_logger().info(summary_line(self.model_description))
        if self.fmu is not None:
            self._check_fmu_plausibility()
        # Latched, and alive while the process runs: a pool hears of a worker whose
        # process or host is gone within its worker_loss_timeout_s (nodes/_pool.py).
        self.model_pub = self.create_publisher(
            String, '~/model', model_qos(float(self.get_parameter('liveliness_lease_s').value)))
        # For an FMU, also how its designs run (recorded in every run configuration).
        if self.fmu is not None:
            self.model_description.update(
                {name: self.get_parameter(name).value
                 for name in ('fmu_isolation', 'fmu_timeout_s', 'fmu_processes')})
        self.model_pub.publish(String(data=dump_yaml(self.model_description)))
        self.clock_pub = self.create_publisher(Clock, '/clock', 10)
        self.state_pub = self.create_publisher(VehicleState, '/vehicle/state', RELIABLE)
        self.valve_link = ValveLink(self)
        self.evaluate_service = serve(self, EvaluateDesign, '~/evaluate', self._on_evaluate,
                                      MutuallyExclusiveCallbackGroup())
        # Its own group: taken while an evaluate request runs.
        self.create_service(Trigger, '~/cancel', self._on_cancel,
                            callback_group=MutuallyExclusiveCallbackGroup())
        self.pub = {name: self.create_publisher(kind, f'~/telemetry/{name}', TELEMETRY)
                    for name, kind in telemetry.TOPICS.items()}
        self.runs = 0
        self.evaluate_calls = 0
        # A pause of the process is logged; a worker started on its own (main) then
        # joins the graph again as a new DDS participant (nodes/_pause.py has why).
        self.pause_watch = PauseWatch(self)

    def _check_fmu_plausibility(self) -> None:
        """Log the FMU's start-up notes; run the plausibility check where it is due.

        ``plausibility_check``: 'auto' runs it when a mapped variable's unit is not
        declared by the FMU, 'always' or 'never'.  Its numbers and warnings go into the
        log and into the model description (``plausibility``).
        """
        log = self.get_logger()
        for note in self.fmu.notes:
            log.info(note)
        mode = str(self.get_parameter('plausibility_check').value)
        if mode not in ('auto', 'always', 'never'):
            log.warning(f'plausibility_check {mode!r} is not auto, always or never: taken as '
                        'auto')
            mode = 'auto'
        if self.fmu.undeclared_units:
            log.info('units the FMU does not declare: ' + '; '.join(self.fmu.undeclared_units))
        if mode == 'never' or (mode == 'auto' and not self.fmu.undeclared_units):
            return
        # Said before the runs: the worker (and a graph starting it) answers nothing
        # until they end, at most this long when they run in child processes.
        budget_s = min(float(self.get_parameter('plausibility_timeout_s').value),
                       float(self.get_parameter('fmu_timeout_s').value))
        scenarios = ', '.join(self.fmu.mapping.scenarios)
        isolated = str(self.get_parameter('fmu_isolation').value) == 'process'
        log.info(f'plausibility check: one run of the centre design in {scenarios}, '
                 + (f'at most {budget_s:g} s in all (plausibility_timeout_s, fmu_timeout_s)'
                    if isolated else 'not bounded (fmu_isolation none)')
                 + '; the worker serves once it ends')
        numbers, warnings = self.fmu.plausibility(budget_s if isolated else None)
        log.info('plausibility check (centre design): ' + ', '.join(
            f'{scenario} ' + ', '.join(f'{k} {v:.3g}' for k, v in found.items())
            for scenario, found in numbers.items()))
        for warning in warnings:
            log.warning(f'plausibility: {warning}')
        self.model_description['plausibility'] = {'numbers': numbers, 'warnings': warnings}

    def _on_evaluate(self, request: EvaluateDesign.Request,
                     response: EvaluateDesign.Response) -> EvaluateDesign.Response:
        start = time.monotonic()
        response.model_fingerprint = self.model_fingerprint
        if self.pause_watch.paused():  # an old participant, matched again for a moment
            response.success, response.error = False, self.pause_watch.paused_error()
            return response
        if not request.scenario and not request.designs:  # a pool's ping
            response.success = True
            return response
        self.evaluate_calls += 1
        try:
            designs = evaluation.parse_designs(request.scenario, int(request.n_vars),
                                               request.designs)
            limit = int(self.get_parameter('max_designs_per_request').value)
            if len(designs) > limit:
                raise ValueError(f'{len(designs)} designs in one request, more than this '
                                 f'worker takes (parameter max_designs_per_request = {limit}): '
                                 'send them in smaller requests, or raise the parameter')
            if self.fmu is None:
                result = evaluation.evaluate(
                    request.scenario, designs, controllers=self._controllers(request, designs),
                    integrator=request.integrator or self.get_parameter('integrator').value,
                    road=request.road, condition=request.condition)
            elif request.condition:
                raise ValueError('an FMU worker runs the vehicle and roads of its mapping '
                                 '(docs/fmu.md); an operating condition is for the built-in '
                                 'model')
            elif request.road:
                raise ValueError('an FMU worker drives the roads its mapping names '
                                 '(docs/fmu.md); a request\'s road is for the built-in model')
            else:
                result = self.fmu.evaluate(request.scenario, designs)
        except ValueError as error:
            response.success = False
            response.error = str(error)
            self.get_logger().warning(f'bad evaluate request: {error}')
            return response
        except FmuRunCancelledError as error:
            response.success = False
            response.error = f'cancelled: {error}'
            self.get_logger().info(response.error)
            return response
        except Exception as error:  # noqa: BLE001 - a failed run must not kill the worker
            response.success = False
            response.error = f'simulation failed: {type(error).__name__}: {error}'
            self.get_logger().error(response.error)
            return response
        self.runs += len(designs)
        response.success = True
        response.model_fingerprint = self.model_fingerprint
        response.n_designs = len(designs)
        response.f = result.f.tolist()
        response.n_constraints = result.g.shape[1]
        response.g = result.g.ravel().tolist()
        response.metric_names = result.metric_names
        response.metrics = result.metrics.ravel().tolist()
        if request.return_inputs:
            response.inputs = [simplified_inputs.pack(
                SimplifiedInputs.from_scenario_result(result.result, i), TimeHistories())
                for i in range(len(designs))]
        if request.publish_telemetry and self.fmu is None:
            self.publish_telemetry(result.result.histories)
        response.wall_time_s = time.monotonic() - start
        return response

    def _controllers(self, request, designs) -> list | None:
        """Valve controllers of a mixed run over ROS (one design at a time)."""
        if request.scenario != 'mixed' or self.get_parameter('valve_controller').value != 'ros':
            return None
        if len(designs) != 1:
            raise ValueError('the mixed scenario runs closed-loop over ROS one design at a '
                             f'time (one valve controller node), got {len(designs)} designs')
        timeout = float(self.get_parameter('closed_loop_timeout_s').value)
        return [TopicValveController(self, timeout)]

    def _on_cancel(self, _request: Trigger.Request,
                   response: Trigger.Response) -> Trigger.Response:
        if self.fmu is None or not hasattr(self.fmu, 'cancel'):
            response.success = False
            response.message = ('this worker runs its model in its own process '
                                f'(model {self.get_parameter("model").value}, fmu_isolation '
                                f'{self.get_parameter("fmu_isolation").value}): a run in '
                                'progress cannot be stopped')
            return response
        response.success = self.fmu.cancel()
        response.message = ('the FMU run in progress was stopped' if response.success
                            else 'no FMU run in progress')
        return response

    def _on_fmu_message(self, message: FmuMessage) -> None:
        """An FMU log message into the worker's log, at its FMI status's level."""
        logger = self.get_logger()
        log = (logger.info if message.status == 0 else logger.warning if message.status < 3
               else logger.error)
        log(f'FMU, design {message.design}, t = {message.time_s:.6g} s: {message}')

    def destroy_node(self) -> None:
        """Close the FMU (if the worker runs one) too."""
        if self.fmu is not None:
            self.fmu.close()
        if getattr(self, 'valve_link', None) is not None:
            self.valve_link.destroy()
        super().destroy_node()

    def publish_telemetry(self, histories: dict[str, np.ndarray], index: int = 0) -> None:
        """Publish the time histories of design ``index`` on the telemetry topics.

        Parameter ``telemetry_rate`` 0 (the default) publishes them at once, as fast as
        the transport takes them: the run's response, and so the optimisation, waits for
        nothing, and the recorder gets every message all the same.  A rate factor r > 0
        paces them at their simulated time divided by r (1.0: as the run happened, at
        the history rate over ``telemetry_decimation``), so that live tools (``ros2 topic
        hz``, a live plot, Foxglove's live connection) see the run as it happens; the
        run's response then comes after its simulated duration / r.  Pacing stops when
        the context shuts down.
        """
        step = max(1, int(self.get_parameter('telemetry_decimation').value))
        rate = float(self.get_parameter('telemetry_rate').value)
        per_topic = telemetry_messages(histories, index, step)
        if not rate > 0.0:
            for name, messages in per_topic.items():
                for message in messages:
                    self.pub[name].publish(message)
            return
        timeline = sorted(
            ((m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec, name, m)
             for name, messages in per_topic.items() for m in messages), key=lambda e: e[:2])
        if not timeline:
            return
        start, t0 = time.monotonic(), timeline[0][0]
        for t_s, name, message in timeline:
            delay = start + (t_s - t0) / rate - time.monotonic()
            if delay > 0.0:
                time.sleep(delay)
            if not self.context.ok():
                return
            self.pub[name].publish(message)


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run suspension_tuning full_vehicle_sim``."""
    try:
        run_node(FullVehicleSimNode, args, name='full_vehicle_sim', rename=True,
                 renew_after_pause=True)
    except (FmuConfigError, MappingError) as error:  # ParameterError, ConfigError: run_node
        import rclpy
        rclpy.try_shutdown()
        print(f'full_vehicle_sim: not started: {error}', file=sys.stderr)
        sys.exit(2)


if __name__ == '__main__':
    main()
