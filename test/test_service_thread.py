"""A service on a thread of its own (suspension_tuning.nodes._service_thread)."""

import contextlib
import threading
import time

import pytest
import rclpy
from suspension_tuning_interfaces.srv import EvaluateDesign

from suspension_tuning.nodes._service_calls import ServiceCaller, ServiceCallError
from suspension_tuning.nodes._service_thread import ServiceLoop, ServiceThread


def _echo(request, response):
    """Answer with the number of designs; a NaN design makes the callback raise."""
    if any(v != v for v in request.designs):
        raise ZeroDivisionError('a NaN design')
    response.success = True
    response.n_designs = len(request.designs) // request.n_vars
    return response


def _request(*designs: float) -> EvaluateDesign.Request:
    return EvaluateDesign.Request(scenario='ride', n_vars=2, designs=list(designs))


@contextlib.contextmanager
def _served(context, callback, namespace: str = '/'):
    """(service, caller, client): ``evaluate`` of a node ``owner``, and a caller of it."""
    owner = rclpy.create_node('owner', namespace=namespace, context=context)
    service = ServiceThread(owner, EvaluateDesign, 'evaluate', callback)
    caller = ServiceCaller(owner)
    try:
        yield service, caller, caller.create_client(EvaluateDesign, service.service_name)
    finally:
        caller.destroy()
        service.destroy()
        owner.destroy_node()


def test_the_service_is_answered_under_the_owners_name_with_no_executor(ros_context):
    with _served(ros_context, _echo, namespace='/ns') as (service, caller, client):
        assert service.service_name == '/ns/owner/evaluate'
        assert client.srv_name == '/ns/owner/evaluate'
        # 6 values of 2 variables: 3 designs.
        response = caller.call(client, _request(0.1, 0.2, 0.3, 0.4, 0.5, 0.6), 10.0, 10.0)
        assert response.success and response.n_designs == 3
        assert service.calls == 1


def test_a_callback_that_raises_is_answered_with_the_error_and_serving_goes_on(ros_context):
    with _served(ros_context, _echo) as (service, caller, client):
        failed = caller.call(client, _request(float('nan'), 0.5), 10.0, 10.0)
        assert not failed.success
        assert failed.error == 'ZeroDivisionError: a NaN design'
        assert caller.call(client, _request(0.5, 0.5), 10.0).n_designs == 1
        assert service.calls == 2


def test_the_thread_stops_on_destroy_and_on_context_shutdown(ros_context):
    owner = rclpy.create_node('owner', context=ros_context)
    first = ServiceThread(owner, EvaluateDesign, 'first', _echo)
    second = ServiceThread(owner, EvaluateDesign, 'second', _echo)
    first.destroy()
    assert not first.loop.alive
    ros_context.shutdown()  # wakes the waiting thread through its guard condition
    second.loop._thread.join(5.0)
    assert not second.loop.alive
    second.destroy()  # after shutdown: no error, nothing left to stop
    owner.destroy_node()


def test_a_callback_returning_no_response_leaves_the_call_unanswered_not_the_thread_dead(
        ros_context):
    answers = iter([None])  # first call: no response object; afterwards: _echo

    def callback(request, response):
        return next(answers, _echo(request, response))

    with _served(ros_context, callback) as (service, caller, client):
        with pytest.raises(ServiceCallError, match='no response within 1.0 s'):
            caller.call(client, _request(0.5, 0.5), 1.0, 10.0)
        assert caller.call(client, _request(0.5, 0.5), 10.0).n_designs == 1
        assert service.calls == 1  # the response that could be sent


def test_services_sharing_a_loop_run_on_one_thread_until_the_last_leaves(ros_context):
    owner = rclpy.create_node('owner', context=ros_context)
    threads: dict[str, set] = {'a': set(), 'b': set()}

    def recording(key):
        def callback(request, response):
            threads[key].add(threading.get_ident())
            return _echo(request, response)
        return callback

    loop = ServiceLoop(ros_context, 'shared')
    a = ServiceThread(owner, EvaluateDesign, 'a', recording('a'), loop=loop)
    b = ServiceThread(owner, EvaluateDesign, 'b', recording('b'), loop=loop)
    caller = ServiceCaller(owner)
    try:
        client_a = caller.create_client(EvaluateDesign, '/owner/a')
        client_b = caller.create_client(EvaluateDesign, '/owner/b')
        for client in (client_a, client_b, client_a):
            assert caller.call(client, _request(0.5, 0.5), 10.0, 10.0).n_designs == 1
        assert threads['a'] == threads['b'] and len(threads['a']) == 1
        a.destroy()
        assert loop.alive  # b is still served
        assert caller.call(client_b, _request(0.5, 0.5), 10.0).success
        b.destroy()
        assert not loop.alive
    finally:
        caller.destroy()
        owner.destroy_node()


def test_a_job_on_the_loop_runs_on_its_thread_and_its_calls_to_the_loop_are_answered_there(
        ros_context):
    """A job waiting for a service of its own loop answers the request itself.

    Without that, the loop's only thread would wait for itself (a deadlock); a nested
    call (a callback that calls another service of the loop) is answered the same way.
    """
    owner = rclpy.create_node('owner', context=ros_context)
    loop = ServiceLoop(ros_context, 'jobs')
    threads: list[int] = []
    caller = ServiceCaller(owner, serve_loop=loop)
    inner_client = caller.create_client(EvaluateDesign, '/owner/inner')

    def inner(request, response):
        threads.append(threading.get_ident())
        return _echo(request, response)

    def outer(request, response):
        threads.append(threading.get_ident())
        # Nested: answered inside this callback's wait; 'outer' itself is not re-entered.
        return caller.call(inner_client, request, 10.0, 10.0)

    services = [ServiceThread(owner, EvaluateDesign, 'inner', inner, loop=loop),
                ServiceThread(owner, EvaluateDesign, 'outer', outer, loop=loop)]
    outer_client = caller.create_client(EvaluateDesign, '/owner/outer')
    try:
        def job(designs):
            threads.append(threading.get_ident())
            return caller.call(outer_client, _request(*designs), 10.0, 10.0).n_designs

        first = loop.submit(job, [0.1, 0.2])
        second = loop.submit(job, [0.1, 0.2, 0.3, 0.4])
        assert (first.result(20.0), second.result(20.0)) == (1, 2)  # in order
        # job, outer, inner per job: all on the loop's thread, none on this one.
        assert len(threads) == 6 and set(threads) == {loop._thread.ident}
        assert [s.calls for s in services] == [2, 2]
    finally:
        for service in services:
            service.destroy()
        caller.destroy()
        owner.destroy_node()
    assert not loop.alive
    with pytest.raises(RuntimeError, match='the loop has stopped'):
        loop.submit(job, [0.5, 0.5])


def test_a_server_gone_since_its_last_answer_is_reported_vanished_not_waited_for(ros_context):
    """The caller skips the availability query for a server that answered last time.

    A request to a server gone since then is noticed after one wait without news
    (1 s), not after the call's timeout (10 s here).
    """
    owner = rclpy.create_node('owner', context=ros_context)
    service = ServiceThread(owner, EvaluateDesign, 'evaluate', _echo)
    caller = ServiceCaller(owner)
    client = caller.create_client(EvaluateDesign, service.service_name)
    try:
        assert caller.call(client, _request(0.5, 0.5), 10.0, 10.0).success
        service.destroy()
        start = time.monotonic()
        with pytest.raises(ServiceCallError, match='vanished while waiting'):
            caller.call(client, _request(0.5, 0.5), 10.0, 10.0)
        assert time.monotonic() - start < 5.0
        # Not answered: the next call asks the graph first, and finds no server.
        with pytest.raises(ServiceCallError, match='not available'):
            caller.call(client, _request(0.5, 0.5), 10.0, 0.5)
    finally:
        caller.destroy()
        owner.destroy_node()


def test_an_action_server_on_a_loop_is_served_there_and_an_awaiting_callback_is_dropped(
        ros_context):
    """LoopActionServer: goal requests are taken on the loop's thread; a goal callback
    that awaits (it cannot be run to its end there) is dropped with an error logged,
    and the loop goes on serving."""
    from rclpy.action import ActionClient, ActionServer
    from rclpy.task import Future
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.nodes._service_thread import LoopActionServer

    owner = rclpy.create_node('owner', context=ros_context)
    loop = ServiceLoop(ros_context, 'test')
    service = ServiceThread(owner, EvaluateDesign, 'evaluate', _echo, loop=loop)
    entered = []

    async def awaiting_goal_callback(goal):
        entered.append(threading.get_ident())
        await Future()  # never done

    server = ActionServer(owner, Optimise, 'optimise', lambda handle: Optimise.Result(),
                          goal_callback=awaiting_goal_callback)
    action = LoopActionServer(owner, server, '/optimise', loop)
    caller = ServiceCaller(owner)
    client = ActionClient(caller.node, Optimise, '/optimise')
    try:
        assert server not in list(owner.waitables)  # no executor of the node takes goals
        assert client.wait_for_server(timeout_sec=10.0)
        client.send_goal_async(Optimise.Goal(scenario='ride', n_vars=2))
        deadline = time.monotonic() + 10.0
        while not entered and time.monotonic() < deadline:
            time.sleep(0.01)
        assert entered == [loop._thread.ident]
        evaluate = caller.create_client(EvaluateDesign, service.service_name)
        assert caller.call(evaluate, _request(0.5, 0.5), 10.0).n_designs == 1
        assert loop.alive
    finally:
        client.destroy()
        caller.destroy()
        action.destroy()
        service.destroy()
        server.destroy()
        owner.destroy_node()
