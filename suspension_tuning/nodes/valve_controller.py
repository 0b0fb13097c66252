"""ROS 2 node ``valve_controller``: 4S4 valve states from the vehicle state.

Subscribes ``/vehicle/state`` (VehicleState, one message per control step of the
simulation) and answers each with the commanded and the actual valve state on
``/suspension/valve_command`` and ``/suspension/valve_state`` (ValveState, carrying
the same ``step``), so that the simulation can run step-locked against it.  The logic
is :class:`suspension_tuning.vehicle.valve_logic.ValveController`; this node only
adapts it to topics and parameters.

Run: ``ros2 run suspension_tuning valve_controller --ros-args --params-file
config/valve_controller.yaml``.
"""

from __future__ import annotations

from dataclasses import asdict, fields

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from suspension_tuning_interfaces.msg import ValveState, VehicleState

from suspension_tuning.config_check import check_config
from suspension_tuning.nodes._parameters import declare_numbers, read_only
from suspension_tuning.nodes._spin import run_node
from suspension_tuning.vehicle.valve_logic import ValveController, ValveControllerParams

#: Commands and valve states must not be dropped (reliable, keep last 100).
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


def to_msg(state: tuple[int, ...], step: int, stamp) -> ValveState:
    """Pack a (front_spring, front_damping, rear_spring, rear_damping) tuple."""
    msg = ValveState()
    msg.header.stamp = stamp
    msg.header.frame_id = 'base_link'
    msg.step = step
    msg.front_spring, msg.front_damping, msg.rear_spring, msg.rear_damping = state
    return msg


class ValveControllerNode(Node):
    """Topic adapter over :class:`ValveController`."""

    def __init__(self, **kwargs) -> None:
        check_config(builtin_model=False)  # ConfigError: one line, before the node exists
        super().__init__('valve_controller', **kwargs)
        defaults = asdict(ValveControllerParams())
        declare_numbers(self, {field.name: float(defaults[field.name])
                               for field in fields(ValveControllerParams)})
        read_only(self, [f.name for f in fields(ValveControllerParams)])  # read once here
        params = ValveControllerParams.from_dict(
            {f.name: self.get_parameter(f.name).value for f in fields(ValveControllerParams)})
        self.controller = ValveController(params)
        self._command_pub = self.create_publisher(ValveState, '/suspension/valve_command',
                                                  RELIABLE)
        self._state_pub = self.create_publisher(ValveState, '/suspension/valve_state',
                                                RELIABLE)
        self.create_subscription(VehicleState, '/vehicle/state', self._on_state, RELIABLE)

    def reset(self) -> None:
        """Start a new run from the ride state (called when a step-0 state arrives)."""
        self.controller = ValveController(self.controller.params)

    def _on_state(self, msg: VehicleState) -> None:
        if msg.step == 0:
            self.reset()
        try:
            commanded, actual = self.controller.update(
                int(msg.step), msg.lateral_acceleration_mps2, msg.roll_rate_radps,
                msg.steering_rate_radps, tuple(msg.strut_pressure_pa))
        except ValueError as error:
            # Keep the valves where they are and still answer, so that a step-locked
            # simulation is never left waiting.
            self.get_logger().error(f'vehicle state of step {msg.step} ignored: {error}')
            commanded, actual = self.controller.commanded, self.controller.actual
        self._command_pub.publish(to_msg(commanded, msg.step, msg.header.stamp))
        self._state_pub.publish(to_msg(actual, msg.step, msg.header.stamp))


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run suspension_tuning valve_controller``."""
    run_node(ValveControllerNode, args, name='valve_controller')


if __name__ == '__main__':
    main()
