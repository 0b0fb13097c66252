"""recorder node: topics, service events and action topics into bags; per run; Ctrl-C; kill."""

import os
import re
import signal
import subprocess
import sys
import time

import pytest
import yaml

from suspension_tuning.testing import wait_until as wait_for

pytestmark = pytest.mark.ros


def latched_qos():
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        depth=1,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


def recorder(ros_context, tmp_path, **params):
    from rclpy.parameter import Parameter

    from suspension_tuning.nodes.recorder import RecorderNode

    values = {
        'output_dir': str(tmp_path / 'bags'),
        'discovery_period_s': 0.1,
        'max_chunk_interval_s': 0.2,
        'exclude_regex': '^/rosout$|^/parameter_events$',
    }
    values.update(params)
    return RecorderNode(
        context=ros_context, parameter_overrides=[Parameter(k, value=v) for k, v in values.items()]
    )


def record_session(ros_context, executor, tmp_path, request):
    """Record progress, IMU, a service's events and an action's topics; return the bag path.

    A fake graph publishes 20 progress records and 20 IMU messages, calls an
    introspected EvaluateDesign service once and runs one Optimise goal (3 feedback
    messages) while the recorder records one session bag.
    """
    from rclpy.action import ActionClient, ActionServer
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from rclpy.service_introspection import ServiceIntrospectionState
    from sensor_msgs.msg import Imu
    from suspension_tuning_interfaces.action import Optimise
    from suspension_tuning_interfaces.msg import IterationRecord
    from suspension_tuning_interfaces.srv import EvaluateDesign

    node = recorder(ros_context, tmp_path, per_run=False, bag_name='session')
    graph = Node('graph_under_test', context=ros_context)
    group = ReentrantCallbackGroup()
    progress = graph.create_publisher(
        IterationRecord,
        '/optimisation/progress',
        QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE),
    )
    imu = graph.create_publisher(Imu, '/sim_0/telemetry/imu', qos_profile_sensor_data)

    def evaluate(request, response):
        response.success = True
        response.f = [2.0 * d for d in request.designs]
        return response

    service = graph.create_service(
        EvaluateDesign, '/sim_0/evaluate', evaluate, callback_group=group
    )
    service.configure_introspection(
        graph.get_clock(), QoSProfile(depth=10), ServiceIntrospectionState.CONTENTS
    )
    client = graph.create_client(EvaluateDesign, '/sim_0/evaluate', callback_group=group)

    def execute(goal_handle):
        for k in range(3):
            feedback = Optimise.Feedback()
            feedback.latest.iteration = k
            goal_handle.publish_feedback(feedback)
            time.sleep(0.05)
        goal_handle.succeed()
        return Optimise.Result(success=True, iterations=3)

    server = ActionServer(graph, Optimise, '/coordinator/optimise', execute,
                          callback_group=group)
    action_client = ActionClient(graph, Optimise, '/coordinator/optimise', callback_group=group)
    # Node.destroy_node leaves action servers and clients alone: left alive, this fake
    # /coordinator/optimise would take the goals of later tests' tune runs unanswered.
    request.addfinalizer(server.destroy)
    request.addfinalizer(action_client.destroy)
    executor.add(node, graph)
    expected = {
        '/optimisation/progress',
        '/sim_0/telemetry/imu',
        '/sim_0/evaluate/_service_event',
        '/coordinator/optimise/_action/feedback',
        '/coordinator/optimise/_action/status',
    }
    assert wait_for(lambda: expected <= set(node.subscribed)), node.subscribed
    assert wait_for(
        lambda: progress.get_subscription_count() > 0 and imu.get_subscription_count() > 0
    )
    for k in range(20):
        progress.publish(IterationRecord(iteration=k, f=float(k)))
        imu_msg = Imu()
        imu_msg.linear_acceleration.z = float(k)
        imu.publish(imu_msg)
        time.sleep(0.005)
    assert client.wait_for_service(timeout_sec=10.0)
    future = client.call_async(
        EvaluateDesign.Request(scenario='ride', n_vars=2, designs=[0.25, 0.5])
    )
    assert wait_for(future.done)
    assert action_client.wait_for_server(timeout_sec=10.0)
    goal_future = action_client.send_goal_async(Optimise.Goal(scenario='ride', n_vars=2))
    assert wait_for(goal_future.done)
    result_future = goal_future.result().get_result_async()
    assert wait_for(result_future.done)
    # 20 progress; best-effort imu on loopback: expect all 20; 2 service events (the
    # server's introspection: REQUEST_RECEIVED, RESPONSE_SENT; the client has none);
    # 3 feedback; status >= 2 (accepted/executing, succeeded)
    counts = lambda: node.session.bag.topics  # noqa: E731
    assert wait_for(
        lambda: (
            node.session.bag is not None
            and counts()['/optimisation/progress'].message_count == 20
            and counts().get('/sim_0/evaluate/_service_event') is not None
            and counts()['/sim_0/evaluate/_service_event'].message_count == 2
            and counts()['/coordinator/optimise/_action/feedback'].message_count == 3
        )
    ), {t: i.message_count for t, i in (counts() if node.session.bag else {}).items()}
    time.sleep(0.3)  # the status update of the finished goal
    path = node.session.bag.path
    node.close()
    return path


def test_records_topics_service_events_and_action_feedback_and_status(
    ros_context, executor, tmp_path, request
):
    from suspension_tuning.bag.reader import decode, read_messages

    path = record_session(ros_context, executor, tmp_path, request)
    contents = read_messages(path)
    assert contents.complete
    got = contents.counts()
    assert got['/optimisation/progress'] == 20
    assert got['/sim_0/telemetry/imu'] == 20
    assert got['/sim_0/evaluate/_service_event'] == 2
    assert got['/coordinator/optimise/_action/feedback'] == 3
    assert got['/coordinator/optimise/_action/status'] >= 2
    types = contents.topics()
    assert (
        types['/sim_0/evaluate/_service_event']
        == 'suspension_tuning_interfaces/srv/EvaluateDesign_Event'
    )
    assert (
        types['/coordinator/optimise/_action/feedback']
        == 'suspension_tuning_interfaces/action/Optimise_FeedbackMessage'
    )
    for message in contents.messages:
        decode(contents, message)  # every message decodes
        assert message.publish_time_ns <= message.log_time_ns  # sent before received
    progress_values = [
        decode(contents, m).iteration for m in contents.on('/optimisation/progress')
    ]
    assert progress_values == list(range(20))  # in order
    events = [decode(contents, m) for m in contents.on('/sim_0/evaluate/_service_event')]
    responses = [e.response[0] for e in events if e.response]
    assert list(responses[0].f) == [0.5, 1.0]  # 2 x designs
    # and with rosbags' AnyReader, a reader we did not write that checks every channel's
    # type hash against its schema text (bytes as Fast DDS delivered them)
    from rosbags.highlevel import AnyReader

    with AnyReader([path]) as reader:
        typestore = reader.typestore
        decoded = 0
        for connection, _, raw in reader.messages():
            msgdef = typestore.get_msgdef(connection.msgtype)
            _, end = msgdef.deserialize_cdr_le(raw[4:], 0, msgdef.cls, typestore)
            assert 0 <= len(raw) - 4 - end <= 8  # payload ends within the DDS sample
            decoded += 1
        assert decoded == contents.message_count
    channels = {c.topic: c for c in contents.channels.values()}
    imu_qos = channels['/sim_0/telemetry/imu'].offered_qos_profiles[0]
    assert imu_qos['reliability'] == 'best_effort'  # the publisher's offer, sensor data
    status_qos = channels['/coordinator/optimise/_action/status'].offered_qos_profiles[0]
    assert status_qos['durability'] == 'transient_local'  # action status is latched


def test_recorded_bag_decodes_with_foxglove_parser_and_cdr_reader(
    foxglove_check, ros_context, executor, tmp_path, request
):
    path = record_session(ros_context, executor, tmp_path, request)
    [result] = foxglove_check([path])
    assert result['complete']
    errors = {c['topic']: c['error'] for c in result['channels'] if c['error']}
    assert not errors
    counts = {c['topic']: (c['decoded'], c['messages']) for c in result['channels']}
    # every channel of the session, service events and action topics included, and
    # every one of its messages (counts as in the test above)
    assert counts['/optimisation/progress'] == (20, 20)
    assert counts['/sim_0/telemetry/imu'] == (20, 20)
    assert counts['/sim_0/evaluate/_service_event'] == (2, 2)
    assert counts['/coordinator/optimise/_action/feedback'] == (3, 3)
    decoded, recorded = counts['/coordinator/optimise/_action/status']
    assert decoded == recorded >= 2
    assert result['ok']


def test_per_run_opens_a_bag_at_run_config_and_closes_it_at_result(
    ros_context, executor, tmp_path
):
    from rclpy.node import Node
    from std_msgs.msg import String
    from suspension_tuning_interfaces.action import Optimise
    from suspension_tuning_interfaces.msg import IterationRecord

    from suspension_tuning.bag.reader import read_messages

    # only the run's topics: an action status left latched on the domain by another
    # test's server would otherwise enter the first bag through the pre-run window
    topics = ['/optimisation/run_config', '/optimisation/progress', '/optimisation/result']
    node = recorder(ros_context, tmp_path, per_run=True, topics=topics)
    graph = Node('coordinator_under_test', context=ros_context)
    config = graph.create_publisher(String, '/optimisation/run_config', latched_qos())
    progress = graph.create_publisher(IterationRecord, '/optimisation/progress', 100)
    result = graph.create_publisher(Optimise.Result, '/optimisation/result', latched_qos())
    executor.add(node, graph)
    expected = {'/optimisation/run_config', '/optimisation/progress', '/optimisation/result'}
    assert wait_for(lambda: expected <= set(node.subscribed))
    assert wait_for(lambda: progress.get_subscription_count() > 0)
    for scenario, n in (('ride', 3), ('handling', 2)):
        config.publish(String(data=f'scenario: {scenario}\nn_vars: 2\ncode_version: abc123\n'))
        time.sleep(0.2)
        for k in range(n):
            progress.publish(IterationRecord(iteration=k))
            time.sleep(0.02)
        time.sleep(0.2)
        result.publish(Optimise.Result(success=True, iterations=n))
        assert wait_for(
            lambda s=scenario: any(b.name.endswith(s) for b in node.session.closed_bags)
        )
    bags = node.session.closed_bags
    assert len(bags) == 2
    for bag, (scenario, n) in zip(bags, (('ride', 3), ('handling', 2))):
        assert re.fullmatch(rf'\d{{8}}-\d{{6}}_{scenario}', bag.name)
        assert (bag / 'metadata.yaml').is_file()
        contents = read_messages(bag)
        assert contents.complete
        assert contents.counts() == {
            '/optimisation/run_config': 1,
            '/optimisation/progress': n,
            '/optimisation/result': 1,
        }
        assert contents.messages[0].topic == '/optimisation/run_config'
        assert contents.messages[-1].topic == '/optimisation/result'
        record = contents.metadata['run_config']
        assert record['scenario'] == scenario and record['code_version'] == 'abc123'
        assert yaml.safe_load(record['yaml'])['n_vars'] == 2
        info = yaml.safe_load((bag / 'metadata.yaml').read_text())
        assert info['rosbag2_bagfile_information']['custom_data'] == {'scenario': scenario}


def start_recorder_process(tmp_path):
    command = [
        sys.executable,
        '-m',
        'suspension_tuning.nodes.recorder',
        '--ros-args',
        '-p',
        'per_run:=false',
        '-p',
        f'output_dir:={tmp_path}',
        '-p',
        'bag_name:=run',
        '-p',
        'max_chunk_interval_s:=0.2',
        '-p',
        'discovery_period_s:=0.1',
    ]
    return subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=dict(os.environ)
    )


def publish_and_wait_recorded(ros_context, executor, process, tmp_path, n):
    """Publish n strings once the recorder subscribed; wait until they are on disk."""
    from rclpy.node import Node
    from std_msgs.msg import String

    from suspension_tuning.bag.reader import read_messages

    talker = Node('talker_under_test', context=ros_context)
    executor.add(talker)
    publisher = talker.create_publisher(String, '/chatter', 100)
    assert wait_for(lambda: publisher.get_subscription_count() > 0, timeout_s=30.0), process.poll()
    for k in range(n):
        publisher.publish(String(data=f'message {k}'))
        time.sleep(0.01)
    mcap = tmp_path / 'run' / 'run_0.mcap'
    # the node flushes the open chunk every 0.2 s: all n are on disk soon after
    assert wait_for(
        lambda: mcap.is_file() and len(read_messages(mcap, topics=['/chatter']).messages) == n,
        timeout_s=10.0,
    )
    return mcap


@pytest.mark.parametrize('stop', [signal.SIGINT, signal.SIGTERM], ids=['ctrl_c', 'sigterm'])
def test_ctrl_c_or_sigterm_finalises_the_bag(ros_context, executor, tmp_path, stop):
    from suspension_tuning.bag.reader import read_messages

    process = start_recorder_process(tmp_path)
    try:
        publish_and_wait_recorded(ros_context, executor, process, tmp_path, 30)
    finally:
        start = time.monotonic()
        process.send_signal(stop)
        output, _ = process.communicate(timeout=20)
    assert time.monotonic() - start < 5.0, output  # stopped like Ctrl-C, at once
    assert process.returncode == 0, output
    assert (tmp_path / 'run' / 'metadata.yaml').is_file()
    contents = read_messages(tmp_path / 'run')
    assert contents.complete  # footer reached: summary written
    # the recorder also records /rosout (its own log lines) and /parameter_events
    assert contents.counts()['/chatter'] == 30
    assert contents.statistics.message_count == contents.message_count


def test_killed_recorder_leaves_a_bag_that_reads_and_reindexes(ros_context, executor, tmp_path):
    from suspension_tuning.bag.reader import decode, read_messages, reindex

    process = start_recorder_process(tmp_path)
    try:
        publish_and_wait_recorded(ros_context, executor, process, tmp_path, 30)
    finally:
        process.kill()  # SIGKILL: no chance to finalise
        process.communicate(timeout=20)
    assert not (tmp_path / 'run' / 'metadata.yaml').exists()
    contents = read_messages(tmp_path / 'run')
    assert not contents.complete
    chatter = [decode(contents, m).data for m in contents.on('/chatter')]
    assert chatter == [f'message {k}' for k in range(30)]
    reindex(tmp_path / 'run')
    repaired = read_messages(tmp_path / 'run')
    assert repaired.complete and repaired.message_count == contents.message_count
    assert repaired.counts()['/chatter'] == 30


def test_session_keeps_the_last_pre_run_second_and_drops_older_messages(tmp_path):
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from suspension_tuning.bag.reader import read_messages
    from suspension_tuning.bag.recorder import RecordingSession

    session = RecordingSession(tmp_path, per_run=True, pre_run_s=1.0, post_run_s=0.0)
    session.add_topic('/optimisation/run_config', 'std_msgs/msg/String')
    session.add_topic('/status', 'std_msgs/msg/String')
    session.add_topic('/optimisation/result', 'std_msgs/msg/String')
    t = 1_700_000_000_000_000_000
    session.write('/status', serialize_message(String(data='old')), t - 3_000_000_000)
    session.write('/status', serialize_message(String(data='accepted')), t - 500_000_000)
    session.write(
        '/optimisation/run_config', serialize_message(String(data='scenario: "ride: 2 vars"\n')), t
    )
    closed = session.write(
        '/optimisation/result', serialize_message(String(data='done')), t + 1_000_000_000
    )
    # 3 s before the run_config: outside the 1 s window; 0.5 s before: inside
    assert session.dropped == 1
    assert closed is not None and closed.name.endswith('_ride-2-vars')  # name sanitised
    contents = read_messages(closed)
    assert [m.topic for m in contents.messages] == [
        '/status',
        '/optimisation/run_config',
        '/optimisation/result',
    ]
    assert contents.metadata['run_config']['scenario'] == 'ride: 2 vars'


def test_session_keeps_a_finished_run_open_for_late_messages(tmp_path):
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from suspension_tuning.bag.reader import read_messages
    from suspension_tuning.bag.recorder import RecordingSession

    session = RecordingSession(tmp_path, per_run=True, pre_run_s=1.0, post_run_s=1.0)
    for topic in ('/optimisation/run_config', '/telemetry', '/optimisation/result'):
        session.add_topic(topic, 'std_msgs/msg/String')
    t = 1_700_000_000_000_000_000
    second = 1_000_000_000
    session.write('/optimisation/run_config', serialize_message(String(data='scenario: ride')), t)
    assert session.write('/optimisation/result', serialize_message(String(data='r')),
                         t + second) is None  # still open: 1 s grace
    # A telemetry sample of the run served after the result, inside the grace period.
    assert session.write('/telemetry', serialize_message(String(data='late')),
                         t + second + second // 2) is None
    assert session.flush(now_ns=t + second + second // 2) is None  # grace not over
    # the late message restarts the 1 s grace: still open 1 s after the result
    assert session.flush(now_ns=t + 2 * second) is None
    closed = session.flush(now_ns=t + 2 * second + second // 2)  # 1 s after the last one
    assert closed is not None
    topics = [m.topic for m in read_messages(closed).messages]
    assert topics == ['/optimisation/run_config', '/optimisation/result', '/telemetry']


def test_session_closes_a_finished_run_at_post_run_max_s_whatever_still_arrives(tmp_path):
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from suspension_tuning.bag.recorder import RecordingSession

    session = RecordingSession(tmp_path, per_run=True, pre_run_s=1.0, post_run_s=1.0,
                               post_run_max_s=5.0)
    for topic in ('/optimisation/run_config', '/telemetry', '/optimisation/result'):
        session.add_topic(topic, 'std_msgs/msg/String')
    t = 1_700_000_000_000_000_000
    second = 1_000_000_000
    session.write('/optimisation/run_config', serialize_message(String(data='scenario: ride')), t)
    session.write('/optimisation/result', serialize_message(String(data='r')), t)
    # a message every 0.5 s keeps the 1 s quiet grace from ever running out ...
    for k in range(1, 10):
        closed = session.write('/telemetry', serialize_message(String(data='x')),
                               t + k * second // 2)
        assert closed is None  # up to 4.5 s after the result
    # ... until the 5 s cap: the message at 5 s finds the bag due and closes it first
    assert session.write('/telemetry', serialize_message(String(data='x')),
                         t + 5 * second) is not None


def test_session_is_not_kept_open_by_messages_published_after_the_result(tmp_path):
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from suspension_tuning.bag.reader import read_messages
    from suspension_tuning.bag.recorder import RecordingSession

    session = RecordingSession(tmp_path, per_run=True, pre_run_s=1.0, post_run_s=1.0)
    for topic in ('/optimisation/run_config', '/telemetry', '/status', '/optimisation/result'):
        session.add_topic(topic, 'std_msgs/msg/String')
    t = 1_700_000_000_000_000_000
    second = 1_000_000_000
    session.write('/optimisation/run_config', serialize_message(String(data='scenario: ride')), t)
    session.write('/optimisation/result', serialize_message(String(data='r')), t + second,
                  publish_time_ns=t + second)
    # the run's telemetry, published before the result, served 0.5 s after it: the 1 s
    # grace restarts (bag due 1.5 s after the result)
    session.write('/telemetry', serialize_message(String(data='late')), t + second // 2,
                  publish_time_ns=t + second // 2, now_ns=t + 3 * second // 2)
    # a status published 1.2 s after the result (past the 1 s grace on the publisher's
    # clock): recorded, but the bag stays due 1.5 s after the result
    assert session.write('/status', serialize_message(String(data='expired')),
                         t + 11 * second // 5, publish_time_ns=t + 11 * second // 5,
                         now_ns=t + 11 * second // 5) is None
    closed = session.flush(now_ns=t + 5 * second // 2)  # 1 s after the telemetry
    assert closed is not None
    topics = [m.topic for m in read_messages(closed).messages]
    assert topics == ['/optimisation/run_config', '/telemetry', '/optimisation/result',
                      '/status']
