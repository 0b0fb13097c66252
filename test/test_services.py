"""The nodes' services and service calls (suspension_tuning.nodes._services)."""

import threading

import pytest
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from suspension_tuning_interfaces.srv import EvaluateDesign

from suspension_tuning.nodes._services import ServiceCallError, call, call_many, serve

pytestmark = pytest.mark.ros


def _echo(request, response):
    """Answer with the number of designs; a NaN design makes the callback raise."""
    if any(v != v for v in request.designs):
        raise ZeroDivisionError('a NaN design')
    response.success = True
    response.n_designs = len(request.designs) // request.n_vars
    return response


def _request(*designs: float) -> EvaluateDesign.Request:
    return EvaluateDesign.Request(scenario='ride', n_vars=2, designs=list(designs))


def _unspun_server_and_caller(context, executor, name: str):
    """(server node, caller node, client): ``/<name>/evaluate`` on a node no executor
    spins (it takes no request), and a caller spun by ``executor``."""
    server = rclpy.create_node(name, context=context)
    serve(server, EvaluateDesign, '~/evaluate', _echo, MutuallyExclusiveCallbackGroup())
    caller = rclpy.create_node('caller', context=context)
    client = caller.create_client(EvaluateDesign, f'/{name}/evaluate',
                                  callback_group=ReentrantCallbackGroup())
    executor.add(caller)
    return server, caller, client


def test_a_callback_that_raises_is_answered_with_the_error_and_serving_goes_on(
        ros_context, executor):
    server = rclpy.create_node('owner', namespace='/ns', context=ros_context)
    # '~/evaluate' resolves below the node's full name.
    serve(server, EvaluateDesign, '~/evaluate', _echo, MutuallyExclusiveCallbackGroup())
    caller = rclpy.create_node('caller', context=ros_context)
    client = caller.create_client(EvaluateDesign, '/ns/owner/evaluate',
                                  callback_group=ReentrantCallbackGroup())
    executor.add(server, caller)
    failed = call(caller, client, _request(float('nan'), 0.5), 10.0)
    assert not failed.success
    assert failed.error == 'ZeroDivisionError: a NaN design'
    # 6 values of 2 variables: 3 designs.
    assert call(caller, client, _request(0.1, 0.2, 0.3, 0.4, 0.5, 0.6), 10.0).n_designs == 3


def test_a_server_that_goes_away_mid_call_is_reported_vanished_not_waited_for(
        ros_context, executor):
    """The server takes no request and goes away 0.5 s into the call, which must say
    so after a poll without news (1 s), not wait for its 60 s timeout (the message
    tells which)."""
    server, caller, client = _unspun_server_and_caller(ros_context, executor, 'leaving')
    assert client.wait_for_service(timeout_sec=10.0)
    leave = threading.Timer(0.5, server.destroy_node)
    leave.start()
    [outcome] = call_many(caller, [(client, _request(0.5, 0.5))], timeout_s=60.0)
    leave.join()
    assert isinstance(outcome, ServiceCallError)
    assert 'vanished while waiting' in str(outcome)
    # No server at all: reported after the wait for the service, no request sent.
    [missing] = call_many(caller, [(client, _request(0.5, 0.5))], 60.0, wait_for_service_s=0.5)
    assert 'not available' in str(missing)


def test_a_wait_ends_when_the_caller_says_it_is_stopping(ros_context, executor):
    """A server that never answers; the caller's node shuts down."""
    server, caller, client = _unspun_server_and_caller(ros_context, executor, 'silent')
    try:
        with pytest.raises(ServiceCallError, match='shut down while waiting'):
            call(caller, client, _request(0.5, 0.5), 60.0, stopping=lambda: True)
    finally:
        server.destroy_node()
