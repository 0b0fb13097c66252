"""A service served by a thread of its own, outside every executor.

The graph's hot services (a simulation worker's ``evaluate``, the gradient
evaluator's ``gradient`` and ``calibrate``) are called once or twice per Dynamic-Q
iteration.  Through rclpy's Python executor each call costs a wait set rebuilt from
every entity of the node (parameter services, publishers' events, ...), a task for the
callback, and after the response the next rebuild, during which the thread keeps the
GIL that the caller's thread needs to take the response.  Measured on the bare
get_parameters round trip of a simulation node: 0.9 ms through its executor, 0.5 ms
through an executor of a node holding only that service, and 0.23 ms with the wait
below (``benchmarks/bench_graph.py``, ``bare_round_trip_ms``).

:class:`ServiceThread` does what the executor does for one service, and nothing else:
a wait set of that service and a guard condition (for shutdown), ``take_request``,
the callback, ``send_response`` (which also publishes the service-introspection
events the recorder keeps).  The service sits on a hidden node of its own
(``_<node>_<service>``) that no executor spins, with the owner's full name, so clients
and ``ros2 service`` see ``/<node>/<service>`` as before; global remaps still apply.
Callbacks run one at a time, in arrival order, as on a SingleThreadedExecutor; the
owner's executor stays free for its parameters, topics and actions.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from rclpy.exceptions import InvalidHandle
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import qos_profile_services_default
from rclpy.service_introspection import ServiceIntrospectionState

from suspension_tuning.nodes._service_calls import hidden_node


class ServiceThread:
    """Serve ``srv_type`` at ``<owner's full name>/<name>`` on a thread of its own.

    Parameters
    ----------
    owner : rclpy.node.Node
        The node the service belongs to (name, namespace, context, logger).
    srv_type : type
        The service type.
    name : str
        The service's name below the owner's, e.g. ``'evaluate'``.
    callback : callable
        ``callback(request, response) -> response``, as for ``Node.create_service``.
        An exception it raises is logged and answered with the empty response (with
        ``success = false`` and the error text where the type has those fields); the
        thread serves on.
    introspection : ServiceIntrospectionState
        Service-introspection events published for each call (default CONTENTS: the
        recorder keeps requests and responses).
    """

    def __init__(self, owner: Node, srv_type: Any, name: str,
                 callback: Callable[[Any, Any], Any],
                 introspection: ServiceIntrospectionState = ServiceIntrospectionState.CONTENTS
                 ) -> None:
        self.owner = owner
        self.srv_type = srv_type
        self.callback = callback
        self.service_name = f'{owner.get_fully_qualified_name().rstrip("/")}/{name}'
        node_name = f'_{owner.get_name()}_{name}'
        self.node = hidden_node(owner, node_name, start_parameter_services=False,
                                enable_rosout=False)
        self.service = self.node.create_service(srv_type, self.service_name, callback)
        self.service.configure_introspection(owner.get_clock(), qos_profile_services_default,
                                             introspection)
        self.calls = 0
        self._stopping = False
        self._wake = GuardCondition(None, None, context=owner.context)
        owner.context.on_shutdown(self._on_shutdown)
        self._thread = threading.Thread(target=self._serve, name=f'serve {self.service_name}',
                                        daemon=True)
        self._thread.start()

    def _on_shutdown(self) -> None:
        self._stop()

    def _stop(self) -> None:
        """Ask the thread to stop and wake it (once; a no-op after :meth:`destroy`)."""
        if not self._stopping:
            self._stopping = True
            self._wake.trigger()

    def _wait(self) -> bool:
        """Block until a request is in (True) or the thread is to stop (False)."""
        context = self.owner.context
        try:
            with self.service.handle, self._wake.handle, context.handle:
                wait_set = _rclpy.WaitSet(0, 1, 0, 0, 1, 0, context.handle)
                wait_set.clear_entities()
                wait_set.add_service(self.service.handle)
                wait_set.add_guard_condition(self._wake.handle)
                wait_set.wait(-1)  # no timeout: the guard condition wakes it to stop
                ready = wait_set.get_ready_entities('service')
                return not self._stopping and self.service.handle.pointer in ready
        except (InvalidHandle, _rclpy.RCLError):
            if self._stopping or not context.ok():
                return False
            raise

    def _serve(self) -> None:
        logger = self.owner.get_logger()
        while not self._stopping:
            try:
                if not self._wait():
                    continue
                with self.service.handle:
                    request, header = self.service.handle.service_take_request(
                        self.srv_type.Request)
            except InvalidHandle:  # destroyed under the wait
                return
            except Exception as error:  # noqa: BLE001 - a wait or take that failed
                if self._stopping or not self.owner.context.ok():
                    return
                logger.error(f'{self.service_name}: no request taken: {error}')
                time.sleep(0.1)  # no hot loop if the failure persists
                continue
            if request is None:  # the middleware had nothing after all
                continue
            self._answer(request, header, logger)

    def _answer(self, request: Any, header: Any, logger: Any) -> None:
        """Run the callback and send its response (or the error, if it raised)."""
        response = self.srv_type.Response()
        try:
            response = self.callback(request, response)
        except Exception as error:  # noqa: BLE001 - answer, log, and serve on
            logger.error(f'{self.service_name} failed: {type(error).__name__}: {error}')
            response = self.srv_type.Response()
            if hasattr(response, 'success') and hasattr(response, 'error'):
                response.success = False
                response.error = f'{type(error).__name__}: {error}'
        try:
            self.service.send_response(response, header)
            self.calls += 1
        except InvalidHandle:  # destroyed while the callback ran
            pass
        except Exception as error:  # noqa: BLE001 - e.g. a field of the wrong type
            logger.error(f'{self.service_name}: response not sent: {error}')

    def destroy(self, timeout_s: float = 5.0) -> None:
        """Stop the thread (after a callback that is running) and destroy the service."""
        self._stop()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout_s)
        self.node.destroy_node()
        self._wake.destroy()
