"""ROS 2 node ``full_vehicle_sim``: the full nonlinear vehicle model as a service.

Service ``~/evaluate`` (EvaluateDesign): a scenario and one or many designs in; the
objective f (eq. 9 or 10), the tyre-hop constraints g (eq. 11), named metrics, the
simplified models' inputs of each design and the wall time out.  A bad request
(unknown scenario, wrong length, NaN, out of bounds) gets ``success = false`` and the
reason in ``error``; the node keeps serving.

On request it publishes the time histories of the first design as telemetry on
standard types, stamped with simulated time: ``~/telemetry/imu`` (sensor_msgs/Imu,
body), ``~/telemetry/struts`` (JointState: stroke m, stroke rate m/s, force N per
strut), ``~/telemetry/tyres`` (JointState: slip angle rad, normal force N),
``~/telemetry/seats`` (JointState: driver and passenger vertical acceleration m/s^2 as
effort) and ``~/telemetry/steering`` (JointState: front road-wheel angle).

Scenario ``mixed`` runs closed-loop against the valve controller on simulated time:
for each control period the node publishes ``/clock`` and ``/vehicle/state`` (step k)
and waits for ``/suspension/valve_state`` answering step k before it integrates on,
so the run is step-locked and deterministic (parameter ``valve_controller``: 'ros',
or 'inprocess' for the same controller without topics).

Several workers run as ``--ros-args -r __node:=sim_0`` etc.; each serves its own
``/<name>/evaluate``.
"""

from __future__ import annotations

import math
import time

import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState
from suspension_tuning_interfaces.msg import TimeHistories, ValveState, VehicleState
from suspension_tuning_interfaces.srv import EvaluateDesign

from suspension_tuning import evaluation, simplified_inputs
from suspension_tuning.nodes._service_calls import helper_node
from suspension_tuning.nodes._service_thread import ServiceLoop, ServiceThread
from suspension_tuning.nodes._spin import run_node
from suspension_tuning.vehicle.params import load_vehicle_params
from suspension_tuning.vehicle.simplified import SimplifiedInputs

CORNERS = ['FL', 'FR', 'RL', 'RR']
#: Vehicle states and valve states must not be dropped in a step-locked run.
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
#: Telemetry of a run is published as one burst after the simulation (thousands of
#: samples within a second), not at sensor rate: a reliable writer deep enough for a
#: whole run keeps every sample for the recorder; best-effort subscribers (plot tools)
#: are compatible with it.
TELEMETRY = QoSProfile(depth=5000, reliability=ReliabilityPolicy.RELIABLE)


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
        sim_time = stamp(node, state['t_s'])
        node.clock_pub.publish(Clock(clock=sim_time))
        msg = VehicleState(step=step, speed_mps=state['speed_mps'],
                           lateral_acceleration_mps2=state['lateral_acceleration_mps2'],
                           roll_angle_rad=state['roll_angle_rad'],
                           roll_rate_radps=state['roll_rate_radps'],
                           steering_angle_rad=state['steering_angle_rad'],
                           steering_rate_radps=state['steering_rate_radps'],
                           strut_pressure_pa=list(state['strut_pressure_pa']))
        msg.header.stamp, msg.header.frame_id = sim_time, 'base_link'
        node.valve_answers.clear()
        # The closed loop runs on a node and executor of its own, spun here by the
        # service callback's thread (as rclpy's wait_for_message does): the answer must
        # not wait for the node's shared executor, which may be busy or asleep.  A state
        # without an answer within a second is published again (the controller's update
        # is idempotent for a repeated step).
        deadline = time.monotonic() + self.timeout_s
        while True:
            node.state_pub.publish(msg)
            resend = min(time.monotonic() + 1.0, deadline)
            while step not in node.valve_answers and time.monotonic() < resend:
                node.loop_executor.spin_once(timeout_sec=0.05)
            if step in node.valve_answers:
                return node.valve_answers[step]
            if time.monotonic() >= deadline:
                raise RuntimeError(f'no valve state for step {step} within {self.timeout_s} '
                                   's: is the valve_controller node running?')
            node.get_logger().warning(f'no valve state for step {step} yet: publishing '
                                      'the vehicle state again')


def stamp(node: Node, t_s: float):
    """A builtin_interfaces/Time of simulated time t_s."""
    msg = node.get_clock().now().to_msg()
    msg.sec = int(math.floor(t_s))
    msg.nanosec = int(round((t_s - math.floor(t_s)) * 1e9)) % 1_000_000_000
    return msg


def quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of body Euler angles roll-pitch-yaw (rad, ZYX convention)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


class FullVehicleSimNode(Node):
    """Service adapter over :func:`suspension_tuning.evaluation.evaluate`."""

    def __init__(self, name: str = 'full_vehicle_sim', service_loop: ServiceLoop | None = None,
                 **kwargs) -> None:
        """``service_loop``: serve ``evaluate`` on this shared loop (default its own)."""
        super().__init__(name, **kwargs)
        self.declare_parameter('telemetry_decimation', 2)
        self.declare_parameter('valve_controller', 'ros')
        self.declare_parameter('closed_loop_timeout_s', 5.0)
        # full-model integrator when a request names none (config/vehicle.yaml default)
        self.declare_parameter('integrator', load_vehicle_params().integrator.method)
        self.loop_node, self.loop_executor = helper_node(self, f'{self.get_name()}_closed_loop')
        self.clock_pub = self.loop_node.create_publisher(Clock, '/clock', 10)
        self.state_pub = self.loop_node.create_publisher(VehicleState, '/vehicle/state',
                                                         RELIABLE)
        self.valve_answers: dict[int, tuple[int, int, int, int]] = {}
        self.loop_node.create_subscription(ValveState, '/suspension/valve_state',
                                           self._on_valve_state, RELIABLE)
        # Served on a thread of its own (no executor in the path of a request).
        self.evaluate_service = ServiceThread(self, EvaluateDesign, 'evaluate',
                                              self._on_evaluate, loop=service_loop)
        self.pub = {name: self.create_publisher(kind, f'~/telemetry/{name}', TELEMETRY)
                    for name, kind in (('imu', Imu), ('struts', JointState),
                                       ('tyres', JointState), ('seats', JointState),
                                       ('steering', JointState))}
        self.runs = 0

    def _on_evaluate(self, request: EvaluateDesign.Request,
                     response: EvaluateDesign.Response) -> EvaluateDesign.Response:
        start = time.monotonic()
        try:
            designs = evaluation.parse_designs(request.scenario, int(request.n_vars),
                                               request.designs)
            result = evaluation.evaluate(
                request.scenario, designs, controllers=self._controllers(request, designs),
                integrator=request.integrator or self.get_parameter('integrator').value)
        except ValueError as error:
            response.success = False
            response.error = str(error)
            self.get_logger().warning(f'bad evaluate request: {error}')
            return response
        except Exception as error:  # noqa: BLE001 - a failed run must not kill the worker
            response.success = False
            response.error = f'simulation failed: {type(error).__name__}: {error}'
            self.get_logger().error(response.error)
            return response
        self.runs += len(designs)
        response.success = True
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
        if request.publish_telemetry:
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

    def _on_valve_state(self, msg: ValveState) -> None:
        self.valve_answers[int(msg.step)] = (msg.front_spring, msg.front_damping,
                                             msg.rear_spring, msg.rear_damping)

    def destroy_node(self) -> None:
        """Destroy the evaluate service's thread and the closed-loop node too."""
        self.evaluate_service.destroy()
        self.loop_executor.shutdown(timeout_sec=1.0)
        self.loop_node.destroy_node()
        super().destroy_node()

    def publish_telemetry(self, histories: dict[str, np.ndarray], index: int = 0) -> None:
        """Publish the time histories of design ``index`` on the telemetry topics."""
        step = max(1, int(self.get_parameter('telemetry_decimation').value))
        h = {name: np.asarray(value)[index] for name, value in histories.items()
             if name != 't_s'}
        for k in range(0, len(histories['t_s']), step):
            now = stamp(self, float(histories['t_s'][k]))
            imu = Imu()
            imu.header.stamp, imu.header.frame_id = now, 'base_link'
            (imu.orientation.x, imu.orientation.y, imu.orientation.z,
             imu.orientation.w) = quaternion(math.radians(h['roll_deg'][k]),
                                             float(h['pitch_rad'][k]), float(h['yaw_rad'][k]))
            imu.angular_velocity.x = math.radians(h['roll_rate_deg_s'][k])
            imu.angular_velocity.z = float(h['yaw_rate_radps'][k])
            imu.linear_acceleration.y = float(h['lateral_accel_mps2'][k])
            imu.linear_acceleration_covariance[0] = -1.0  # only lateral is known
            self.pub['imu'].publish(imu)
            self.pub['struts'].publish(JointState(
                header=imu.header, name=CORNERS,
                position=h['strut_stroke_m'][:, k].tolist(),
                effort=h['strut_force_n'][:, k].tolist()))
            self.pub['tyres'].publish(JointState(
                header=imu.header, name=CORNERS, position=h['slip_angle_rad'][:, k].tolist(),
                effort=h['tyre_fz_n'][:, k].tolist()))
            self.pub['seats'].publish(JointState(
                header=imu.header, name=['driver', 'passenger'],
                effort=[float(h['acc_driver_mps2'][k]), float(h['acc_passenger_mps2'][k])]))
            self.pub['steering'].publish(JointState(
                header=imu.header, name=['front_road_wheel'],
                position=[float(h['steer_rad'][k])],
                velocity=[float(h['steer_rate_radps'][k])]))


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run suspension_tuning full_vehicle_sim``."""
    run_node(FullVehicleSimNode, args, multithreaded=True)


if __name__ == '__main__':
    main()
