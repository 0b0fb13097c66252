"""A valve-control strategy of our own: the 4S4 valves switched on lateral acceleration.

Both axles go to the handling state (stiff spring, high damping) once the lateral
acceleration reaches ``on_mps2`` and back to the ride state (soft, low) once it falls
below ``off_mps2``; the valves are taken to switch at once (no solenoid delay, no
dwell time).  The node talks to the simulation like the package's valve controller:
it answers each ``/vehicle/state`` with ``/suspension/valve_command`` and
``/suspension/valve_state`` carrying the same step.
"""

from __future__ import annotations

from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from suspension_tuning_interfaces.msg import ValveState, VehicleState

from suspension_tuning.vehicle.valve_logic import HANDLING_STATE, RIDE_STATE

#: The simulation waits for every answer of a step-locked run: reliable, keep last 100.
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


class LateralValveController(Node):
    """Ride or handling state from the lateral acceleration alone, with hysteresis."""

    def __init__(self, **kwargs) -> None:
        super().__init__('valve_controller', **kwargs)
        # The switching thresholds of the package's controller
        # (config/valve_controller.yaml, lateral_acceleration_on/off_mps2).
        self.on_mps2 = float(self.declare_parameter('on_mps2', 2.0).value)
        self.off_mps2 = float(self.declare_parameter('off_mps2', 1.0).value)
        self.state = RIDE_STATE
        self.switches = 0
        self.command_pub = self.create_publisher(ValveState, '/suspension/valve_command',
                                                 RELIABLE)
        self.state_pub = self.create_publisher(ValveState, '/suspension/valve_state',
                                               RELIABLE)
        self.create_subscription(VehicleState, '/vehicle/state', self.on_state, RELIABLE)

    def on_state(self, msg: VehicleState) -> None:
        """Answer one control step."""
        if msg.step == 0:  # a new run starts in the ride state
            self.state = RIDE_STATE
        lateral = abs(msg.lateral_acceleration_mps2)
        wanted = (HANDLING_STATE if lateral >= self.on_mps2
                  else RIDE_STATE if lateral < self.off_mps2 else self.state)
        if wanted != self.state:
            self.switches += 1
            self.state = wanted
        answer = ValveState(step=msg.step)
        answer.header = msg.header
        (answer.front_spring, answer.front_damping,
         answer.rear_spring, answer.rear_damping) = self.state
        self.command_pub.publish(answer)
        self.state_pub.publish(answer)
