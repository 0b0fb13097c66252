"""valve_controller node on a real executor: answers every vehicle state, in step."""

import threading

import pytest

pytestmark = pytest.mark.ros


def test_node_answers_each_step_and_switches_after_the_valve_delay(ros_context, executor):
    from rclpy.node import Node
    from suspension_tuning_interfaces.msg import ValveState, VehicleState

    from suspension_tuning.nodes.valve_controller import RELIABLE, ValveControllerNode
    from suspension_tuning.vehicle.valve_logic import HANDLING_STATE, RIDE_STATE

    node = ValveControllerNode(context=ros_context)
    client = Node('valve_test_client', context=ros_context)
    executor.add(node, client)
    received: dict[int, tuple[int, ...]] = {}
    commands: dict[int, tuple[int, ...]] = {}
    arrived = threading.Condition()

    def on_state(msg):
        with arrived:
            received[msg.step] = (msg.front_spring, msg.front_damping, msg.rear_spring,
                                  msg.rear_damping)
            arrived.notify_all()

    def on_command(msg):
        commands[msg.step] = (msg.front_spring, msg.front_damping, msg.rear_spring,
                              msg.rear_damping)

    client.create_subscription(ValveState, '/suspension/valve_state', on_state, RELIABLE)
    client.create_subscription(ValveState, '/suspension/valve_command', on_command,
                               RELIABLE)
    publisher = client.create_publisher(VehicleState, '/vehicle/state', RELIABLE)
    while publisher.get_subscription_count() == 0:
        threading.Event().wait(0.05)
    period = node.controller.params.control_period_s
    # Step-locked: publish step k, wait for its answer.  From step 20 the vehicle
    # turns (3 m/s^2 > 2 m/s^2 switch-on level).  Strut pressure 4 MPa = pressure_high
    # -> the shortest delay, 50 ms (paper section 3).
    for step in range(60):
        msg = VehicleState()
        msg.step = step
        msg.lateral_acceleration_mps2 = 3.0 if step >= 20 else 0.0
        msg.strut_pressure_pa = [4.0e6] * 4
        msg.header.stamp.nanosec = int(step * period * 1e9)
        publisher.publish(msg)
        with arrived:
            assert arrived.wait_for(lambda k=step: k in received, timeout=10.0), step
    assert received[19] == RIDE_STATE
    assert commands[20] == HANDLING_STATE
    first_actual = min(k for k, state in received.items() if state == HANDLING_STATE)
    assert (first_actual - 20) * period == pytest.approx(0.050)
