"""replay node: republishes a bag in the recorded order and spacing (times 1/rate)."""

import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

pytestmark = pytest.mark.ros

#: Recorded gaps between consecutive messages, ns: 10, 20, 30, 40 ms repeating, so that
#: a replay at fixed spacing would be caught.
GAPS_NS = [10_000_000, 20_000_000, 30_000_000, 40_000_000]
N = 40  # messages: 39 gaps, 0.975 s recorded
#: Tolerance on each send-time gap, s.  The replay thread sleeps until an absolute
#: target on the monotonic clock (Linux wakes it within ~0.1 ms), but in this test it
#: shares the GIL with the executor threads of the listener: CPython hands the GIL to a
#: waiting thread after at most sys.getswitchinterval() = 5 ms, so one wake-up can be
#: late by one to two switch intervals; measured on this shared 2-core machine: median
#: 0.02 ms, worst 8.3 ms when idle; with both cores busy with other processes an OS
#: preemption delayed single wake-ups by up to 38 ms (median 4.9 ms); one fresh-clone
#: CI run of the whole suite had a 90th percentile of 20.0 ms, four whole switch
#: intervals (errors of 5.0, 10.0, 15.0 and 20.0 ms).  So: 90 % of the gaps within
#: 25 ms (five switch intervals), none beyond 100 ms (a scheduler time slice on a loaded
#: machine), and the median below 5 ms (a replay at fixed spacing would err by 15 ms in
#: median, and that is what the median check catches).
GAP_TOLERANCE_S = 0.025
WORST_GAP_TOLERANCE_S = 0.100
MEDIAN_TOLERANCE_S = 0.005


def write_stream(path):
    """N strings alternating on /replay/a and /replay/b, a latched config first."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from suspension_tuning.bag.writer import BagWriter, qos_profile_dict

    sent = []
    with BagWriter(path) as bag:
        bag.add_topic('/replay/a', 'std_msgs/msg/String', [qos_profile_dict(depth=100)])
        bag.add_topic(
            '/replay/b', 'std_msgs/msg/String', [qos_profile_dict('best_effort', depth=100)]
        )
        t = 1_700_000_000_000_000_000
        for k in range(N):
            topic = '/replay/a' if k % 3 else '/replay/b'
            bag.write(topic, serialize_message(String(data=f'{k}')), t)
            sent.append((topic, f'{k}', t))
            t += GAPS_NS[k % len(GAPS_NS)]
    return sent


def listen(ros_context, executor):
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    listener = Node('replay_listener', context=ros_context)
    received = []
    lock = threading.Lock()

    def on(topic):
        def callback(msg, info):
            with lock:
                received.append((topic, msg.data, info['source_timestamp']))

        return callback

    for topic, reliability in (
        ('/replay/a', ReliabilityPolicy.RELIABLE),
        ('/replay/b', ReliabilityPolicy.BEST_EFFORT),
    ):
        listener.create_subscription(
            String, topic, on(topic), QoSProfile(depth=100, reliability=reliability)
        )
    executor.add(listener)
    return received


@pytest.mark.parametrize('rate', [1.0, 2.0])
def test_replay_keeps_order_and_spacing(ros_context, executor, tmp_path, rate):
    from rclpy.parameter import Parameter

    from suspension_tuning.nodes.replay import ReplayNode

    sent = write_stream(tmp_path / 'bag')
    received = listen(ros_context, executor)
    node = ReplayNode(
        context=ros_context,
        parameter_overrides=[
            Parameter('bag', value=str(tmp_path / 'bag')),
            Parameter('rate', value=rate),
            Parameter('start_delay_s', value=1.0),
        ],
    )  # discovery on loopback takes < 1 s
    executor.add(node)
    assert node.done.wait(timeout=20.0)
    deadline = time.monotonic() + 5.0
    while len(received) < N and time.monotonic() < deadline:
        time.sleep(0.05)
    assert node.published == N
    assert len(received) == N  # loopback: even the best-effort topic loses nothing
    # order: by send time the messages come out exactly as recorded
    by_send = sorted(received, key=lambda r: r[2])
    assert [(t, d) for t, d, _ in by_send] == [(t, d) for t, d, _ in sent]
    # spacing: send-time gaps equal the recorded gaps / rate
    expected = np.diff([s[2] for s in sent]) / 1e9 / rate
    actual = np.diff([r[2] for r in by_send]) / 1e9
    error = actual - expected
    print(
        f'rate {rate}: gap error median {np.median(np.abs(error)) * 1e3:.3f} ms, '
        f'max {np.max(np.abs(error)) * 1e3:.3f} ms'
    )
    assert np.percentile(np.abs(error), 90) < GAP_TOLERANCE_S
    assert np.max(np.abs(error)) < WORST_GAP_TOLERANCE_S
    assert np.median(np.abs(error)) < MEDIAN_TOLERANCE_S
    # no drift: absolute targets, the whole stream lasts duration / rate
    total = (by_send[-1][2] - by_send[0][2]) / 1e9
    recorded = (sent[-1][2] - sent[0][2]) / 1e9
    assert total == pytest.approx(recorded / rate, abs=WORST_GAP_TOLERANCE_S)


def test_replay_restores_latching_and_publishes_clock(ros_context, executor, tmp_path):
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.serialization import serialize_message
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import String

    from suspension_tuning.bag.writer import BagWriter, qos_profile_dict
    from suspension_tuning.nodes.replay import ReplayNode

    with BagWriter(tmp_path / 'bag') as bag:
        bag.add_topic(
            '/optimisation/run_config',
            'std_msgs/msg/String',
            [qos_profile_dict('reliable', 'transient_local', depth=1)],
        )
        bag.write(
            '/optimisation/run_config',
            serialize_message(String(data='scenario: ride')),
            5_000_000_123,
        )
    clocks = []
    clock_listener = Node('clock_listener', context=ros_context)
    clock_listener.create_subscription(Clock, '/clock', lambda m: clocks.append(m.clock), 10)
    executor.add(clock_listener)
    node = ReplayNode(
        context=ros_context,
        parameter_overrides=[
            Parameter('bag', value=str(tmp_path / 'bag')),
            Parameter('publish_clock', value=True),
            Parameter('start_delay_s', value=1.0),
        ],
    )  # discovery on loopback takes < 1 s
    executor.add(node)
    late = Node('late_listener', context=ros_context)
    assert node.done.wait(timeout=10.0)
    # a subscriber that arrives after playback still gets the latched configuration
    got = []
    late.create_subscription(
        String,
        '/optimisation/run_config',
        lambda m: got.append(m.data),
        QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        ),
    )
    executor.add(late)
    deadline = time.monotonic() + 10.0
    while not got and time.monotonic() < deadline:
        time.sleep(0.05)
    assert got == ['scenario: ride']
    assert node.published == 1
    # /clock carried the recorded log time, 5.000000123 s
    assert [(c.sec, c.nanosec) for c in clocks] == [(5, 123)]


def test_replay_executable_finishes_by_itself(tmp_path):
    write_stream(tmp_path / 'bag')
    command = [
        sys.executable,
        '-m',
        'suspension_tuning.nodes.replay',
        '--ros-args',
        '-p',
        f'bag:={tmp_path / "bag"}',
        '-p',
        'rate:=4.0',
        '-p',
        'start_delay_s:=0.1',
    ]
    started = time.monotonic()
    result = subprocess.run(
        command, capture_output=True, text=True, timeout=60, env=dict(os.environ)
    )
    assert result.returncode == 0, result.stderr
    assert f'replay done: {N} messages published' in result.stderr + result.stdout
    # 0.975 s recorded / 4 + 0.1 s delay + start-up; well under the 60 s timeout
    assert time.monotonic() - started < 30.0


@pytest.mark.parametrize('bag, message', [
    ('missing_bag', 'does not exist'),
    ('garbage.mcap', 'not an MCAP file'),
])
def test_replay_of_an_unreadable_bag_says_why_and_exits_2(tmp_path, bag, message):
    path = tmp_path / bag
    if bag.endswith('.mcap'):
        path.write_bytes(b'this is not a bag')
    run = subprocess.run([sys.executable, '-m', 'suspension_tuning.nodes.replay', '--ros-args',
                          '-p', f'bag:={path}'], capture_output=True, text=True, timeout=60)
    assert run.returncode == 2
    assert message in run.stderr
