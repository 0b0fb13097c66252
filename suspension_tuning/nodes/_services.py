"""Services of the nodes, and service calls made from their callbacks.

A callback that calls a service (the coordinator's goal, the gradient evaluator's
calibration) waits for the response on its own thread while another thread of the
node's MultiThreadedExecutor takes it: the node's clients sit in a callback group
that the waiting callback does not hold (rclpy's ``Client.call`` contract).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from rclpy.callback_groups import CallbackGroup
from rclpy.node import Node
from rclpy.qos import qos_profile_services_default
from rclpy.service_introspection import ServiceIntrospectionState

#: Longest wait between looks at a server that may have vanished, s.  Shorter waits
#: wake the waiting thread more often, and each wake-up takes the GIL from the thread
#: running a model (with 0.1 s waits a 0.7 s batch ran 50-70 ms slower).
POLL_S = 1.0


class ServiceCallError(RuntimeError):
    """A service did not answer: not available, timed out, vanished or shut down."""


def serve(node: Node, srv_type: Any, name: str, callback: Callable[[Any, Any], Any],
          group: CallbackGroup) -> Any:
    """``node.create_service`` with its calls introspected and its errors answered.

    The requests and responses go onto ``<name>/_service_event`` (contents: the
    recorder keeps them).  An exception of ``callback`` is logged and answered with
    ``success = false`` and the error text (where the type has those fields), instead
    of ending the executor's spin.
    """
    def answered(request: Any, response: Any) -> Any:
        try:
            return callback(request, response)
        except Exception as error:  # noqa: BLE001 - answer, log, and serve on
            message = f'{type(error).__name__}: {error}'
            node.get_logger().error(f'{service.service_name} failed: {message}')
            response = srv_type.Response()
            if hasattr(response, 'success') and hasattr(response, 'error'):
                response.success, response.error = False, message
            return response

    service = node.create_service(srv_type, name, answered, callback_group=group)
    service.configure_introspection(node.get_clock(), qos_profile_services_default,
                                    ServiceIntrospectionState.CONTENTS)
    return service


def call_many(node: Node, calls: Sequence[tuple[Any, Any]], timeout_s: float,
              wait_for_service_s: float = 5.0,
              stopping: Callable[[], bool] = lambda: False) -> list[Any]:
    """Send several requests at once and wait for all of them (from a callback).

    Parameters
    ----------
    node : rclpy.node.Node
        The clients' node, spun by an executor on other threads.
    calls : sequence of (client, request)
        Clients of ``node`` in a callback group the caller does not hold.
    timeout_s : float
        Time each request may take, s.
    wait_for_service_s : float
        Time to wait for a service to appear, s.
    stopping : callable
        True when the caller's node is shutting down or its goal is cancelled: stop
        waiting.

    Returns
    -------
    list
        Per call, in order: the response, or a :class:`ServiceCallError` saying why
        there is none (unavailable, timed out, vanished, shut down).
    """
    outcomes: list[Any] = [None] * len(calls)
    news = threading.Condition()
    pending: dict[int, Any] = {}

    def arrived(_future: Any) -> None:
        with news:
            news.notify_all()

    for i, (client, request) in enumerate(calls):
        if not client.wait_for_service(timeout_sec=wait_for_service_s):
            outcomes[i] = ServiceCallError(f'service {client.srv_name} not available')
            continue
        pending[i] = client.call_async(request)
        pending[i].add_done_callback(arrived)
    deadline = time.monotonic() + timeout_s
    while pending:
        with news:
            came = news.wait_for(lambda: any(f.done() for f in pending.values()), POLL_S)
        ended = not node.context.ok() or stopping()
        expired = time.monotonic() > deadline
        for i, future in list(pending.items()):
            client = calls[i][0]
            if future.done():
                error = future.exception()
                outcomes[i] = (ServiceCallError(f'service {client.srv_name} failed: {error}')
                               if error is not None else future.result())
            elif ended:
                outcomes[i] = ServiceCallError(f'service {client.srv_name}: shut down while '
                                               'waiting')
            elif expired:
                outcomes[i] = ServiceCallError(f'service {client.srv_name}: no response '
                                               f'within {timeout_s} s')
            elif not came and not client.service_is_ready():
                outcomes[i] = ServiceCallError(f'service {client.srv_name} vanished while '
                                               'waiting')
            else:
                continue
            if not future.done():
                client.remove_pending_request(future)
            del pending[i]
    return outcomes


def call(node: Node, client: Any, request: Any, timeout_s: float,
         stopping: Callable[[], bool] = lambda: False) -> Any:
    """One call of :func:`call_many`; its response.

    Raises
    ------
    ServiceCallError
        No response (see :func:`call_many`).
    """
    outcome = call_many(node, [(client, request)], timeout_s, stopping=stopping)[0]
    if isinstance(outcome, ServiceCallError):
        raise outcome
    return outcome
