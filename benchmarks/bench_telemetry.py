"""Live telemetry's pacing: the rate a subscriber in another process receives.

Starts ``graph --telemetry-rate FACTOR`` as a user does (its own process, loopback
discovery, a domain of its own), subscribes to ``/full_vehicle_sim/telemetry/imu`` from
this process and sends ``--goals`` one-run goals (gradient source 'evaluate': one
full-model run of the 30 s ride).  Per goal, the receive rate is the messages received
less one over the time between the first and the last; the configured rate is the
history rate over ``telemetry_decimation`` times the factor (config/vehicle.yaml
``history_decimation`` 2 of the 500 Hz steps: 250 Hz; config/graph.yaml
``telemetry_decimation`` 2: 125 Hz at factor 1).

Prints ``telemetry_configured_hz``, ``telemetry_rate_hz`` (median over the goals),
``telemetry_rate_ratio`` (received over configured; target 0.8-1.2: the pacing holds
the run's simulated time over the factor), ``telemetry_messages_per_run`` and
``telemetry_lost_messages`` (the run's 3,750 IMU messages less those received; a
RELIABLE subscription, so 0).  On a loaded machine the ratio falls below 1 where the
publisher or this subscriber falls behind; above 1 the pacing is broken.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', '93')

import numpy as np  # noqa: E402

BIN = Path(sys.executable).parent
#: Telemetry rate per topic at factor 1, Hz (module docstring).
LIVE_RATE_HZ = 125.0
#: IMU messages of one ride run: 30 s (config/scenarios.yaml) at 125 Hz.
MESSAGES_PER_RUN = 3750


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--factor', type=float, default=3.0,
                        help='telemetry_rate of the simulation node (default 3: the 30 s '
                             'run in 10 s; 0: unpaced, every message at once)')
    parser.add_argument('--goals', type=int, default=3, help='one-run goals (default 3)')
    args = parser.parse_args(argv)

    import rclpy
    from rclpy.action import ActionClient
    from rclpy.executors import MultiThreadedExecutor
    from rclpy.node import Node
    from sensor_msgs.msg import Imu
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.nodes._spin import wait_future
    from suspension_tuning.nodes.full_vehicle_sim import TELEMETRY

    bags = tempfile.mkdtemp(prefix='bench_telemetry_')
    graph = subprocess.Popen([str(BIN / 'graph'), '--telemetry-rate', str(args.factor),
                              '--ros-args', '-p', f'output_dir:={bags}'],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    rclpy.init()
    node = Node('bench_telemetry')
    received: list[float] = []
    lock = threading.Lock()

    def on_imu(_message: Imu) -> None:
        with lock:
            received.append(time.monotonic())

    node.create_subscription(Imu, '/full_vehicle_sim/telemetry/imu', on_imu, TELEMETRY)
    client = ActionClient(node, Optimise, '/coordinator/optimise')
    executor = MultiThreadedExecutor(num_threads=2)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    rates, counts = [], []
    try:
        if not client.wait_for_server(timeout_sec=90.0):
            print('bench_telemetry: the coordinator did not come up within 90 s',
                  file=sys.stderr)
            return 1
        goal = Optimise.Goal(scenario='ride', n_vars=2, gradient_source='evaluate')
        for _ in range(args.goals):
            with lock:
                received.clear()
            wait_future(wait_future(client.send_goal_async(goal)).get_result_async())
            time.sleep(1.0)  # the last messages in flight
            with lock:
                times = list(received)
            counts.append(len(times))
            if len(times) > 1:
                rates.append((len(times) - 1) / (times[-1] - times[0]))
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown()
        graph.send_signal(signal.SIGINT)
        graph.communicate(timeout=60)
    configured = LIVE_RATE_HZ * args.factor
    rate = float(np.median(rates)) if rates else 0.0
    print(f'telemetry_configured_hz: {configured:g}')  # 0: unpaced (--factor 0)
    print(f'telemetry_rate_hz: {rate:.1f}')
    if configured > 0.0:
        print(f'telemetry_rate_ratio: {rate / configured:.3f}')
    print(f'telemetry_messages_per_run: {int(np.median(counts)) if counts else 0}')
    print(f'telemetry_lost_messages: {sum(MESSAGES_PER_RUN - c for c in counts)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
