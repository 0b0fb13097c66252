"""The coordinator survives a simulation worker that dies mid-run.

Two workers run as separate processes (``full_vehicle_sim`` renamed sim_0 and sim_1,
started like ``ros2 run`` would).  One is killed (SIGKILL) after the first iteration;
its loss is noticed through DDS liveliness, its pending designs are sent to the other
worker, and the optimisation still returns a result.  The other one is killed and
restarted at once under its name: it is taken back without losing a piece.  With
every worker gone the goal fails with a clear message.
"""

import signal
import subprocess
import sys
import threading
import time

import pytest
from rclpy.parameter import Parameter

from suspension_tuning.testing import wait_for_future as wait

pytestmark = pytest.mark.ros

TIMEOUT_S = 8.0  # a worker is declared hung after this per design (one takes < 1 s)


def start_worker(name, log_dir):
    exe = [sys.executable, '-m', 'suspension_tuning.nodes.full_vehicle_sim']
    log = open(log_dir / f'{name}.log', 'w')  # noqa: SIM115 - closed with the process
    return subprocess.Popen([*exe, '--ros-args', '-r', f'__node:={name}',
                             '-p', 'telemetry_decimation:=50'],
                            stdout=log, stderr=subprocess.STDOUT)


def worker_logs(log_dir):
    """The workers' output, for the message of a failed assertion."""
    return '\n'.join(f'--- {path.name}\n{path.read_text()[-3000:]}'
                     for path in sorted(log_dir.glob('*.log')))


def test_optimisation_survives_a_killed_worker_and_fails_clearly_without_any(
        ros_context, executor, tmp_path):
    from rclpy.action import ActionClient
    from rclpy.node import Node
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.nodes.coordinator import CoordinatorNode

    workers = {name: start_worker(name, tmp_path) for name in ('sim_0', 'sim_1')}
    try:
        coordinator = CoordinatorNode(context=ros_context, parameter_overrides=[
            Parameter('sim_workers', value=['/sim_0', '/sim_1']),
            Parameter('design_timeout_s', value=TIMEOUT_S),
            Parameter('final_telemetry', value=False)])
        client_node = Node('pool_test_client', context=ros_context)
        executor.add(coordinator, client_node)
        deadline = time.monotonic() + 60.0
        while coordinator.pool.alive != ['/sim_0', '/sim_1']:
            assert time.monotonic() < deadline, 'workers did not come up'
            time.sleep(0.2)
        client = ActionClient(client_node, Optimise, '/coordinator/optimise')
        assert client.wait_for_server(timeout_sec=10.0)
        killed = threading.Event()
        killed_at = []

        def on_feedback(feedback):
            if not killed.is_set():  # kill sim_0 after the first iteration
                killed_at.append(time.monotonic())
                workers['sim_0'].send_signal(signal.SIGKILL)
                killed.set()

        # Full-model gradients: each gradient is a batch of 2n = 4 designs spread over
        # both workers, so the dead worker's share must be redone elsewhere.
        handle = wait(client.send_goal_async(
            Optimise.Goal(scenario='handling', n_vars=2, gradient_source='full',
                          max_iterations=3), feedback_callback=on_feedback))
        result = wait(handle.get_result_async()).result
        assert killed.is_set()
        assert result.success or 'maximum number of iterations' in result.message, \
            result.message + '\n' + worker_logs(tmp_path)
        assert result.iterations >= 1 and len(result.x) == 2
        assert coordinator.pool.alive == ['/sim_1'], worker_logs(tmp_path)
        # Noticed through DDS liveliness within worker_loss_timeout_s (2 s,
        # config/graph.yaml's default), with 1.5 s for a loaded machine.
        lost = [e for e in coordinator.pool.events if e.kind == 'lost' and e.worker == '/sim_0']
        assert lost and lost[0].time_s - killed_at[0] <= 2.0 + 1.5, list(coordinator.pool.events)
        # sim_1 crashes and is restarted at once under its name, while the dead process
        # is still listed on the graph (DDS lease 20 s): the pool takes it back once it
        # answers a ping, so its first piece is not lost and waited for design_timeout_s
        # (docs/distributed.md: without the ping, 1 of 4 such restarts lost a piece).
        workers['sim_1'].send_signal(signal.SIGKILL)
        workers['sim_1'].wait(timeout=10)
        killed_at = [time.monotonic()]
        workers['sim_1'] = start_worker('sim_1', tmp_path)

        def back():
            return [e for e in coordinator.pool.events
                    if e.kind == 'back' and e.worker == '/sim_1' and e.time_s > killed_at[0]]

        while not back():
            assert time.monotonic() - killed_at[0] < 60.0, worker_logs(tmp_path)
            time.sleep(0.2)
        assert back()[0].time_s - killed_at[0] < 20.0  # within the dead process's lease
        events_before = len(coordinator.pool.events)
        handle = wait(client.send_goal_async(
            Optimise.Goal(scenario='handling', n_vars=2, gradient_source='full',
                          max_iterations=1)))
        restarted = wait(handle.get_result_async()).result
        assert restarted.success or 'maximum number of iterations' in restarted.message, \
            restarted.message + '\n' + worker_logs(tmp_path)
        resent = [e for e in list(coordinator.pool.events)[events_before:]
                  if e.kind == 'resent']
        assert not resent, resent
        # Now the last worker dies too: the goal fails with a clear error.
        workers['sim_1'].send_signal(signal.SIGKILL)
        workers['sim_1'].wait(timeout=10)
        handle = wait(client.send_goal_async(
            Optimise.Goal(scenario='handling', n_vars=2, gradient_source='full',
                          max_iterations=2)))
        failed = wait(handle.get_result_async()).result
        assert not failed.success
        assert 'no simulation worker' in failed.message, failed.message
    finally:
        for process in workers.values():
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
                try:
                    process.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    process.kill()
