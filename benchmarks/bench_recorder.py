"""Bag layer throughput: writer and reader messages/s and MB/s, truncation recovery.

Prints ``name: value`` lines.  Telemetry-like load: sensor_msgs/JointState with 4
joints (position, velocity, effort), as the struts topic publishes at every step.
"""

import random
import tempfile
import time
from pathlib import Path

from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

from suspension_tuning.bag.reader import read_messages
from suspension_tuning.bag.writer import BagWriter, qos_profile_dict

N = 100_000  # messages: 20 s of 4 topics at 200 Hz is 16 000, so this is 6 such runs


def main() -> None:
    msg = JointState(
        name=['FL', 'FR', 'RL', 'RR'], position=[0.01] * 4, velocity=[0.1] * 4, effort=[4000.0] * 4
    )
    data = serialize_message(msg)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / 'bench'
        start = time.perf_counter()
        with BagWriter(path) as bag:
            bag.add_topic(
                '/sim_0/telemetry/struts',
                'sensor_msgs/msg/JointState',
                [qos_profile_dict('best_effort', depth=10)],
            )
            t = 1_700_000_000_000_000_000
            for _ in range(N):
                bag.write('/sim_0/telemetry/struts', data, t)
                t += 5_000_000
        elapsed = time.perf_counter() - start
        size = bag.mcap_path.stat().st_size
        print(f'message_bytes: {len(data)}')
        print(f'write_messages_per_s: {N / elapsed:.0f}')
        print(f'write_payload_MB_per_s: {N * len(data) / elapsed / 1e6:.1f}')
        print(f'file_bytes_per_message: {size / N:.2f}')
        print(f'chunks: {bag.chunk_count}')
        start = time.perf_counter()
        contents = read_messages(path)
        elapsed = time.perf_counter() - start
        assert contents.message_count == N
        print(f'read_messages_per_s: {N / elapsed:.0f}')
        raw = bag.mcap_path.read_bytes()
        rng = random.Random(8)
        for _ in range(5):
            cut = rng.randrange(len(raw))
            partial = Path(tmp) / 'cut.mcap'
            partial.write_bytes(raw[:cut])
            count = read_messages(partial).message_count
            # a file cut at p % of its bytes keeps about p % of the messages, less up
            # to one chunk (the one the cut falls in)
            print(f'truncated_at_{100 * cut / len(raw):.1f}pct_messages_recovered: {count}')
        print(f'messages_per_chunk: {N / bag.chunk_count:.0f}')


def bench_node(n: int = 4_000) -> None:
    """Recorder node in-process: a reliable publisher sends n struts messages at once.

    n stays below Fast DDS's default reader resource limit (max_samples 5000): a
    larger burst than the recorder drains in time loses samples.
    """
    import os

    if os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE') != 'LOCALHOST':
        print('recorder_node: skipped (set ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)')
        return
    import threading

    import rclpy
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from suspension_tuning.nodes.recorder import RecorderNode

    rclpy.init()
    for label, make in (
        ('single_threaded', SingleThreadedExecutor),
        ('multi_threaded', lambda: MultiThreadedExecutor(num_threads=2)),
    ):
        with tempfile.TemporaryDirectory() as tmp:
            recorder = RecorderNode(
                parameter_overrides=[
                    Parameter('output_dir', value=tmp),
                    Parameter('per_run', value=False),
                    Parameter('discovery_period_s', value=0.1),
                    Parameter('topics', value=['/struts']),
                ]
            )
            talker = Node('bench_talker')
            pub = talker.create_publisher(
                JointState, '/struts', QoSProfile(depth=n, reliability=ReliabilityPolicy.RELIABLE)
            )
            executor = make()
            executor.add_node(recorder)
            executor.add_node(talker)
            thread = threading.Thread(target=executor.spin, daemon=True)
            thread.start()
            while pub.get_subscription_count() == 0:
                time.sleep(0.05)
            msg = JointState(
                name=['FL', 'FR', 'RL', 'RR'],
                position=[0.01] * 4,
                velocity=[0.1] * 4,
                effort=[4000.0] * 4,
            )
            start = time.perf_counter()
            for _ in range(n):
                pub.publish(msg)
            while recorder.received < n and time.perf_counter() - start < 60:
                time.sleep(0.01)
            elapsed = time.perf_counter() - start
            print(f'recorder_node_{label}_messages_received: {recorder.received} of {n}')
            print(f'recorder_node_{label}_messages_per_s: {recorder.received / elapsed:.0f}')
            executor.shutdown()
            thread.join(timeout=5)
            recorder.destroy_node()
            talker.destroy_node()
    rclpy.try_shutdown()


if __name__ == '__main__':
    main()
    bench_node()
