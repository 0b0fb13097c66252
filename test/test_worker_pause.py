"""A simulation worker says so after a pause of its process, and what to do about it.

The pause is made by moving the worker's last look at the clock back past
``PAUSE_S`` (what a SIGSTOP that long leaves behind; test_pool_restarts.py stops a real
process, which then joins the graph again as a new participant).
"""

from __future__ import annotations

import time

import pytest

pytestmark = pytest.mark.ros


def test_a_pause_longer_than_half_the_dds_lease_is_logged_with_the_remedy(
        ros_context, executor, capfd):
    from suspension_tuning.nodes._pause import PAUSE_S
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode
    from suspension_tuning.testing import wait_until

    sim = FullVehicleSimNode(name='paused_sim', context=ros_context)
    executor.add(sim)
    time.sleep(2.5)  # two looks at the clock without a pause: nothing said
    assert 'was paused' not in capfd.readouterr().err
    sim.pause_watch.last_look -= PAUSE_S + 5.0  # the process did not run meanwhile
    said = []  # stderr as it comes

    def paused_said() -> bool:
        said.append(capfd.readouterr().err)
        return 'was paused' in ''.join(said)

    assert wait_until(paused_said, 5.0, period_s=0.2)
    err = ''.join(said)
    assert 'this process was paused for 1' in err  # 15-16 s: the moved look, a tick
    # a node in a process of the graph's (not renewed): the remedy is said
    assert 'if no "worker /paused_sim is back" follows' in err
    assert 'restart the process' in err
    assert not sim.pause_watch.renewal_due.is_set()


def test_a_worker_that_renews_answers_paused_until_its_new_participant_is_up(
        ros_context, executor):
    from rclpy.node import Node
    from suspension_tuning_interfaces.srv import EvaluateDesign

    from suspension_tuning.nodes._pause import PAUSE_S, PAUSED_ERROR
    from suspension_tuning.nodes._spin import wait_future
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode

    sim = FullVehicleSimNode(name='renewing_sim', context=ros_context)
    sim.pause_watch.renew = True  # as run_node(..., renew_after_pause=True) sets it
    caller = Node('pause_caller', context=ros_context)
    executor.add(sim)
    executor.add(caller)
    client = caller.create_client(EvaluateDesign, '/renewing_sim/evaluate')
    assert client.wait_for_service(timeout_sec=10.0)
    ping = EvaluateDesign.Request()  # no scenario, no designs: a pool's ping
    assert wait_future(client.call_async(ping), 10.0).success
    sim.pause_watch.last_look -= PAUSE_S + 5.0  # the process did not run meanwhile
    answer = wait_future(client.call_async(ping), 10.0)
    # the first request after the pause, before the timer's next look: not an answer
    assert not answer.success
    assert answer.error.startswith(PAUSED_ERROR)
    assert 'joins the graph again as a new DDS participant' in answer.error
    assert sim.pause_watch.renewal_due.is_set()  # run_node now makes the node again


def test_a_worker_made_again_keeps_the_parameters_set_while_it_ran(ros_context, executor):
    from rclpy.parameter import Parameter

    from suspension_tuning.nodes._spin import changeable_parameters, kept_parameters
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode

    first = FullVehicleSimNode(name='renewed_sim', context=ros_context)
    # as `ros2 param set /renewed_sim telemetry_rate 1.5` would (default 0: at once)
    assert first.set_parameters([Parameter('telemetry_rate', value=1.5)])[0].successful
    saved = changeable_parameters(first)
    names = [p.name for p in saved]
    assert 'telemetry_rate' in names and 'model' not in names  # model: read-only
    first.destroy_node()
    second = FullVehicleSimNode(name='renewed_sim', context=ros_context)
    try:
        assert second.get_parameter('telemetry_rate').value == 0.0  # as made
        assert kept_parameters(second, saved) == ['telemetry_rate']  # only what differs
        assert second.get_parameter('telemetry_rate').value == 1.5
    finally:
        second.destroy_node()
