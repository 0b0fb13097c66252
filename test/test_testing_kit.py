"""The testing kit (suspension_tuning.testing): contexts, executors, timeouts, bags.

The graph through the kit (``start_tuning_graph``, a replaced node, the recorded
bag) is exercised by test_resume.py and by the example project under examples/.
"""

import os
import subprocess
import sys
import threading

import pytest

from suspension_tuning.testing import (
    CallbackError,
    RosTimeoutError,
    TuningGraph,
    call_service,
    isolated_context,
    open_bag,
    reserved_domain,
    send_goal,
    spinning_executor,
    tuning_graph,
    wait_for_bag,
    wait_for_future,
    wait_until,
)

pytestmark = pytest.mark.ros


def test_the_session_domain_is_reserved_on_the_machine_and_shared_in_the_process(
        ros_domain_id):
    import domain_coordinator

    # A second reservation, launch_testing's own, starting at the session's domain:
    # the session holds that one, so it gets the next free one.
    after = iter([ros_domain_id, *range(10, 100)])  # the kit's range, 10..99
    with domain_coordinator.domain_id(selector=lambda: next(after)) as other:
        assert other != ros_domain_id
    # The kit's blocks without a domain id take the session's domain.
    with reserved_domain() as domain, isolated_context() as context:
        assert domain == ros_domain_id == context.get_domain_id()
    with reserved_domain(ros_domain_id) as domain:  # asked for by number: shared too
        assert domain == ros_domain_id


def test_another_process_never_gets_the_session_domain(ros_domain_id):
    # A process whose search starts at the session's domain (as a pid would make it)
    # moves on to a free one; asking for the session's domain by number is refused.
    code = ('from suspension_tuning.testing import _environment as env\n'
            f'env.default_domain_id = lambda: {ros_domain_id}\n'
            'with env.reserved_domain() as domain:\n'
            '    print(domain)\n'
            'try:\n'
            f'    with env.reserved_domain({ros_domain_id}):\n'
            '        pass\n'
            'except env.DomainInUseError as error:\n'
            '    print(error)\n')
    child = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                           timeout=120, check=True)
    domain, refusal = child.stdout.splitlines()
    assert int(domain) != ros_domain_id and 10 <= int(domain) <= 99
    assert refusal.startswith(f'ROS domain {ros_domain_id} is reserved by another process '
                              f'on this machine (TCP port {32768 + ros_domain_id} is bound')


def test_a_session_asking_for_a_held_domain_stops_and_says_how_to_choose(
        tmp_path, ros_domain_id):
    # Two sessions in one folder of their own (the package's plugin, no conftest.py):
    # one asks for this session's domain, the other takes a free one and frees it.
    (tmp_path / 'pytest.ini').write_text('[pytest]\n')
    (tmp_path / 'test_domain.py').write_text(
        'def test_domain(ros_domain_id):\n'
        '    open("domain.txt", "w").write(str(ros_domain_id))\n')

    def session(*options):
        return subprocess.run([sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider',
                               *options], cwd=tmp_path, capture_output=True, text=True,
                              timeout=120)

    held = session('--ros-domain-id', str(ros_domain_id))
    assert held.returncode == pytest.ExitCode.USAGE_ERROR, held.stdout + held.stderr
    assert (f'ERROR: --ros-domain-id {ros_domain_id}: ROS domain {ros_domain_id} is '
            'reserved by another process on this machine') in held.stderr
    assert ('Choose another with --ros-domain-id N, or leave the option out: the session '
            'then takes a free domain.') in held.stderr
    assert not (tmp_path / 'domain.txt').exists()  # no test ran
    free = session()
    assert free.returncode == 0, free.stdout + free.stderr
    theirs = int((tmp_path / 'domain.txt').read_text())
    assert theirs != ros_domain_id
    with reserved_domain(theirs):  # freed when that session ended
        pass


def test_a_context_is_on_loopback_on_its_domain_and_the_environment_comes_back(
        monkeypatch, ros_domain_id):
    # A shell configured for the real network: the kit overrides it while the
    # context lives (loopback is enforced right before rclpy.init) and restores it.
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'SUBNET')
    monkeypatch.setenv('ROS_STATIC_PEERS', '192.0.2.1')  # TEST-NET-1 (RFC 5737)
    shut_down = []
    with isolated_context(ros_domain_id) as context:
        context.on_shutdown(lambda: shut_down.append(True))
        assert context.ok()
        assert context.get_domain_id() == ros_domain_id
        assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
        assert 'ROS_STATIC_PEERS' not in os.environ
    assert shut_down == [True]
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'SUBNET'
    assert os.environ['ROS_STATIC_PEERS'] == '192.0.2.1'


def test_a_context_is_shut_down_when_the_test_body_fails(ros_domain_id):
    shut_down = []
    with pytest.raises(AssertionError), isolated_context(ros_domain_id) as context:
        context.on_shutdown(lambda: shut_down.append(True))
        raise AssertionError('the test failed')
    assert shut_down == [True]


def test_a_future_nobody_completes_times_out_naming_what_was_awaited():
    from rclpy.task import Future

    with pytest.raises(RosTimeoutError, match=r'^the probe: no answer within 0.2 s$'):
        wait_for_future(Future(), 0.2, 'the probe')


def test_a_missing_service_is_reported_by_name_and_type(ros_context, ros_executor):
    from rclpy.node import Node
    from suspension_tuning_interfaces.srv import EvaluateDesign

    node = Node('kit_client', context=ros_context)
    ros_executor.add(node)
    client = node.create_client(EvaluateDesign, '/nobody/evaluate')
    with pytest.raises(RosTimeoutError) as raised:
        call_service(client, EvaluateDesign.Request(), server_timeout_s=0.5)
    assert str(raised.value) == ('service /nobody/evaluate (suspension_tuning_interfaces/'
                                 'srv/EvaluateDesign): not available after 0.5 s')


def test_a_service_that_does_not_answer_in_time_is_reported_by_name(ros_context, ros_executor):
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.node import Node
    from suspension_tuning_interfaces.srv import EvaluateDesign

    release = threading.Event()

    def held(request, response):
        release.wait(30.0)
        return response

    node = Node('kit_server', context=ros_context)
    node.create_service(EvaluateDesign, '/held/evaluate', held,
                        callback_group=ReentrantCallbackGroup())
    ros_executor.add(node)
    client = node.create_client(EvaluateDesign, '/held/evaluate')
    try:
        with pytest.raises(RosTimeoutError, match=r'^service /held/evaluate .*: no answer '
                                                  r'within 0.5 s$'):
            call_service(client, EvaluateDesign.Request(), timeout_s=0.5)
    finally:
        release.set()


def _optimise_server(node, execute):
    from rclpy.action import ActionServer, CancelResponse
    from rclpy.callback_groups import ReentrantCallbackGroup
    from suspension_tuning_interfaces.action import Optimise

    return ActionServer(node, Optimise, '/kit/optimise', execute,
                        cancel_callback=lambda _: CancelResponse.ACCEPT,
                        callback_group=ReentrantCallbackGroup())


def test_a_goal_ends_with_its_status_result_and_feedback(ros_context, ros_executor):
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient
    from rclpy.node import Node
    from suspension_tuning_interfaces.action import Optimise
    from suspension_tuning_interfaces.msg import IterationRecord

    def execute(goal_handle):
        for k in range(2):
            goal_handle.publish_feedback(Optimise.Feedback(latest=IterationRecord(iteration=k)))
        goal_handle.succeed()
        return Optimise.Result(success=True, iterations=2)

    node = Node('kit_action', context=ros_context)
    server = _optimise_server(node, execute)
    ros_executor.add(node)
    received = []
    try:
        outcome = send_goal(ActionClient(node, Optimise, '/kit/optimise'),
                            Optimise.Goal(scenario='ride', n_vars=2), timeout_s=30.0,
                            feedback_callback=received.append, action_name='/kit/optimise')
    finally:
        ros_executor.remove(node)  # no spin holds the server when it is destroyed
        server.destroy()
    assert outcome.status == GoalStatus.STATUS_SUCCEEDED
    assert outcome.result.success and outcome.result.iterations == 2
    # Feedback and result travel on different topics: the two feedback messages sent
    # before the result may still be in flight when it arrives, never more than two.
    assert [f.latest.iteration for f in outcome.feedback] == [0, 1][:len(outcome.feedback)]
    assert received == outcome.feedback


def test_an_unfinished_goal_times_out_naming_the_action_and_is_cancelled(
        ros_context, ros_executor):
    from rclpy.action import ActionClient
    from rclpy.node import Node
    from suspension_tuning_interfaces.action import Optimise

    cancelled = threading.Event()

    def execute(goal_handle):
        while not goal_handle.is_cancel_requested:
            threading.Event().wait(0.02)
        cancelled.set()
        goal_handle.canceled()
        return Optimise.Result(success=False, message='cancelled')

    node = Node('kit_action', context=ros_context)
    server = _optimise_server(node, execute)
    ros_executor.add(node)
    try:
        with pytest.raises(RosTimeoutError, match=r'^action /kit/optimise \(suspension_tuning_'
                                                  r'interfaces/action/Optimise\): result: no '
                                                  r'answer within 1 s$'):
            send_goal(ActionClient(node, Optimise, '/kit/optimise'),
                      Optimise.Goal(scenario='ride', n_vars=2), timeout_s=1.0,
                      action_name='/kit/optimise')
        assert cancelled.wait(10.0), 'the timed-out goal was not cancelled'
    finally:
        ros_executor.remove(node)  # no spin holds the server when it is destroyed
        server.destroy()


def test_a_callback_that_raises_fails_the_block_after_spinning_on(ros_context):
    from rclpy.node import Node

    calls = []

    def tick():
        calls.append(1)
        if len(calls) == 1:
            raise ValueError('the first tick fails')

    with pytest.raises(CallbackError, match='1 callback.*ValueError: the first tick fails'):
        with spinning_executor(ros_context) as spinning:
            node = Node('kit_timer', context=ros_context)
            node.create_timer(0.01, tick)
            spinning.add(node)
            assert wait_until(lambda: len(calls) >= 3, 10.0), 'spinning stopped at the error'


def test_a_bag_is_handed_out_only_once_closed_and_only_once(tmp_path):
    from suspension_tuning.bag.writer import BagWriter

    bag = BagWriter(tmp_path / 'run_a')
    bag.add_topic('/a', 'std_msgs/msg/String')
    bag.write('/a', b'\x00\x01\x00\x00\x02\x00\x00\x00x\x00', 1)  # CDR of String('x')
    bag.flush()
    with pytest.raises(RosTimeoutError, match=r"still open: \['run_a'\]"):
        wait_for_bag(tmp_path, timeout_s=0.3)
    bag.close()
    assert wait_for_bag(tmp_path, timeout_s=5.0) == tmp_path / 'run_a'
    contents = open_bag(tmp_path / 'run_a')
    assert contents.counts() == {'/a': 1}
    with pytest.raises(RosTimeoutError, match=r"closed: \['run_a'\]"):
        wait_for_bag(tmp_path, timeout_s=0.3, known={tmp_path / 'run_a'})


def test_replacing_or_configuring_a_node_the_graph_does_not_have_is_an_error(ros_context):
    from rclpy.node import Node

    # graph.build_nodes' own check of its factories.
    with pytest.raises(ValueError, match=r"no node valve_control in the graph to replace; "
                                         r"its nodes: full_vehicle_sim, "):
        TuningGraph(ros_context, replace={'valve_control': lambda **kw: Node('x', **kw)})
    # A recorder's parameters, but no recorder (no record_dir): said, not ignored.
    with pytest.raises(ValueError, match=r"no node named \['recorder'\] in the graph to set "
                                         r"parameters on"):
        TuningGraph(ros_context, parameters={'recorder': {'post_run_s': 0.5}})


def test_each_graph_node_spins_on_the_executor_it_asks_for_as_under_ros2_run(ros_context):
    """The kit spins the step-locked valve controller single-threaded, as ``ros2 run``
    does (nodes/_spin.py ``executor_for``), so a mixed run over topics answers every
    step in time; the nodes that wait on other callbacks get their thread pools."""
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
    from rclpy.node import Node
    from suspension_tuning_interfaces.srv import EvaluateDesign

    class OwnController(Node):  # a test's own node: no EXECUTOR attribute
        def __init__(self, **kwargs):
            super().__init__('valve_controller', **kwargs)

    with tuning_graph(ros_context) as graph:
        kinds = {s.nodes[0].get_name(): type(s.executor) for s in graph.spinners}
        assert kinds['valve_controller'] is SingleThreadedExecutor
        for name in ('full_vehicle_sim', 'gradient_evaluator', 'coordinator'):
            assert kinds[name] is MultiThreadedExecutor, name
        # One design of the closed-loop scenario, every control step answered over
        # topics: about 2 s, where a multi-threaded valve controller timed out on 2 cores.
        response = graph.call(EvaluateDesign, '/full_vehicle_sim/evaluate',
                              EvaluateDesign.Request(scenario='mixed', n_vars=2,
                                                     designs=[0.5005, 0.5005]),
                              timeout_s=120.0)
        assert response.success, response.error
    with tuning_graph(ros_context, replace={'valve_controller': OwnController}) as graph:
        kinds = {s.nodes[0].get_name(): type(s.executor) for s in graph.spinners}
        assert kinds['valve_controller'] is SingleThreadedExecutor
