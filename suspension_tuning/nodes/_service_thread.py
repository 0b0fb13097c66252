"""Services served by threads of their own, outside every executor.

The graph's hot services (a simulation worker's ``evaluate``, the gradient
evaluator's ``gradient`` and ``calibrate``) are called once or twice per Dynamic-Q
iteration.  Through rclpy's Python executor each call costs a wait set rebuilt from
every entity of the node (parameter services, publishers' events, ...), a task for the
callback, and after the response the next rebuild, during which the thread keeps the
GIL that the caller's thread needs to take the response.  Measured on the bare
get_parameters round trip of a simulation node: 0.9 ms through its executor, 0.5 ms
through an executor of a node holding only that service, and 0.23 ms with the wait
below (``benchmarks/bench_graph.py``, ``bare_round_trip_ms``).

A :class:`ServiceLoop` does what an executor does for services, and nothing else: a
wait set of its services and a guard condition (for changes and shutdown),
``take_request``, the callback, ``send_response`` (which also publishes the
service-introspection events the recorder keeps).  Callbacks run one at a time, in
arrival order, as on a SingleThreadedExecutor; the owners' executors stay free for
their parameters, topics and actions.

A :class:`ServiceThread` is one service on a hidden node of its own
(``_<node>_<service>``) that no executor spins, with the owner's full name, so clients
and ``ros2 service`` see ``/<node>/<service>`` as before; global remaps still apply.
It has a loop of its own unless it is given one to share.  The graph in one process
(``graph.build_nodes``) serves the first simulation worker's ``evaluate``, the
gradient evaluator's ``gradient`` and ``calibrate`` and the coordinator's action server
(:class:`LoopActionServer`) on one loop, which also runs the coordinator's goals
(:meth:`ServiceLoop.submit`): both models run on one thread and
share numba's OpenMP team, as in-process (on a thread of its own, the gradient's team
has slept since the previous iteration, and each 4-design simplified batch took
1.5 ms longer: 4.2 against 2.6-2.7 ms, ``benchmarks/bench_model_threads.py``), and a
goal or a calibration waiting for one of the loop's services answers it on its own
thread (``_service_calls.ServiceCaller``).
"""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any

from rclpy.exceptions import InvalidHandle
from rclpy.guard_condition import GuardCondition
from rclpy.node import Node
from rclpy.qos import qos_profile_services_default
from rclpy.service_introspection import ServiceIntrospectionState

from suspension_tuning.nodes._service_calls import hidden_node, wait_ready


class ServiceLoop:
    """A thread serving services one request at a time (see the module docstring).

    It also runs jobs handed to it (:meth:`submit`), between requests: the graph in
    one process runs the coordinator's goals here.  A job's service calls made
    through a :class:`~suspension_tuning.nodes._service_calls.ServiceCaller` that
    serves this loop answer the loop's requests while they wait (:meth:`serve`), so
    a call to a service of the same loop is answered on the calling thread, with no
    hand-over between threads (the model loop of ``graph.build_nodes``).

    It stops when its last service is removed or when the context shuts down.

    Parameters
    ----------
    context : rclpy.context.Context
        Context of the services it will serve.
    name : str
        Names the thread (``serve <name>``).
    """

    def __init__(self, context: Any, name: str) -> None:
        self.context = context
        # ServiceThreads and LoopActionServers: what the loop waits on and serves.
        self._entries: list[Any] = []
        self._active: list[Any] = []  # callbacks running on this thread
        self._jobs: collections.deque[tuple[Future, Callable[..., Any], tuple]] = (
            collections.deque())
        self._lock = threading.Lock()
        self._stopping = False
        self._wake = GuardCondition(None, None, context=context)
        self._wake_destroyed = False
        context.on_shutdown(self._on_shutdown)
        self._thread = threading.Thread(target=self._serve, name=f'serve {name}', daemon=True)
        self._thread.start()

    @property
    def alive(self) -> bool:
        """Whether the thread still runs."""
        return self._thread.is_alive()

    def on_thread(self) -> bool:
        """Whether the caller runs on the loop's thread (in a callback or a job)."""
        return threading.current_thread() is self._thread

    def submit(self, function: Callable[..., Any], *args: Any) -> Future:
        """Run ``function(*args)`` on the loop's thread, after the request in hand.

        Jobs run one at a time, in order; a job is not started inside another job's
        wait.  Returns a ``concurrent.futures.Future`` of its result.

        Raises
        ------
        RuntimeError
            The loop has stopped.
        """
        future: Future = Future()
        with self._lock:
            if self._stopping or not self._thread.is_alive():
                raise RuntimeError(f'{self._thread.name}: the loop has stopped')
            self._jobs.append((future, function, args))
        self._kick()
        return future

    def idle(self) -> list[Any]:
        """The services a wait on the loop's thread may serve: those not in a callback.

        A callback waiting for a response (``calibrate`` for the simulation's
        samples) is not entered again from its own wait.
        """
        with self._lock:
            return [entry for entry in self._entries if entry not in self._active]

    def serve(self, entry: Any) -> None:
        """Take and answer one request of ``entry`` (on the loop's thread)."""
        self._active.append(entry)
        try:
            entry._take_and_answer()
        finally:
            self._active.remove(entry)

    def add(self, entry: Any) -> None:
        """Serve ``entry`` too (from the next wait on)."""
        with self._lock:
            self._entries.append(entry)
        self._kick()

    def remove(self, entry: Any, timeout_s: float = 5.0) -> None:
        """Serve ``entry`` no more; the last one removed stops the thread."""
        with self._lock:
            if entry in self._entries:
                self._entries.remove(entry)
            last = not self._entries
        if last:
            self.stop(timeout_s)
        else:
            self._kick()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop the thread (after a callback that is running)."""
        if not self._stopping:
            self._stopping = True
            self._kick()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout_s)
        with self._lock:
            if not self._wake_destroyed:
                self._wake_destroyed = True
                self._wake.destroy()

    def _on_shutdown(self) -> None:
        self._stopping = True
        self._kick()

    def _kick(self) -> None:
        """Wake the wait (to rebuild it, or to stop)."""
        try:
            self._wake.trigger()
        except InvalidHandle:  # destroyed: the thread has stopped already
            pass

    def _wait(self) -> list[Any]:
        """Block until requests are in (their entries) or something changed ([])."""
        entries = self.idle()
        _, ready = wait_ready(self.context, -1, services=[e.service for e in entries],
                              guards=[self._wake])  # no timeout: the guard wakes it
        return [entry for entry in entries if entry.service in ready]

    def _run_job(self) -> None:
        """Run the oldest job, if any (requests in meanwhile go first, then the next)."""
        with self._lock:
            if not self._jobs:
                return
            future, function, args = self._jobs.popleft()
            if self._jobs:
                self._kick()
        if not future.set_running_or_notify_cancel():
            return
        try:
            future.set_result(function(*args))
        except BaseException as error:  # noqa: BLE001 - handed to whoever waits
            future.set_exception(error)

    def _serve(self) -> None:
        try:
            self._serve_until_stopped()
        finally:
            with self._lock:  # no job is queued after this: submit() sees _stopping
                self._stopping = True
                jobs, self._jobs = list(self._jobs), collections.deque()
            for future, _, _ in jobs:
                future.cancel()

    def _serve_until_stopped(self) -> None:
        while not self._stopping:
            try:
                ready = self._wait()
            except Exception as error:  # noqa: BLE001 - a wait that failed
                if self._stopping or not self.context.ok():
                    return
                with self._lock:
                    entries = list(self._entries)
                if entries:
                    entries[0].owner.get_logger().error(f'service wait failed: {error}')
                time.sleep(0.1)  # no hot loop if the failure persists
                continue
            for entry in ready:
                if self._stopping:
                    return
                self.serve(entry)
            self._run_job()


class ServiceThread:
    """Serve ``srv_type`` at ``<owner's full name>/<name>`` outside the owner's executor.

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
        loop serves on.
    introspection : ServiceIntrospectionState
        Service-introspection events published for each call (default CONTENTS: the
        recorder keeps requests and responses).
    loop : ServiceLoop, optional
        The loop to be served by, shared with other services; default a loop (and
        thread) of its own.
    """

    def __init__(self, owner: Node, srv_type: Any, name: str,
                 callback: Callable[[Any, Any], Any],
                 introspection: ServiceIntrospectionState = ServiceIntrospectionState.CONTENTS,
                 loop: ServiceLoop | None = None) -> None:
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
        self.loop = loop or ServiceLoop(owner.context, self.service_name)
        self.loop.add(self)

    def _take_and_answer(self) -> None:
        """Take one request, run the callback, send its response (on the loop's thread)."""
        logger = self.owner.get_logger()
        try:
            with self.service.handle:
                request, header = self.service.handle.service_take_request(
                    self.srv_type.Request)
        except InvalidHandle:  # destroyed under the wait
            return
        except Exception as error:  # noqa: BLE001 - e.g. a request that does not convert
            logger.error(f'{self.service_name}: no request taken: {error}')
            return
        if request is None:  # the middleware had nothing after all
            return
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
        """Leave the loop (the last one stops it, after a running callback) and destroy."""
        self.loop.remove(self, timeout_s)
        self.node.destroy_node()


class LoopActionServer:
    """An action server's requests (goal, cancel, result) taken by a :class:`ServiceLoop`.

    The server leaves its node's executor: the loop waits on it beside its services
    and runs rclpy's request handling (``take_data``, then the ``execute`` coroutine,
    which with synchronous callbacks ends in one step) on its thread.  With the
    coordinator's goals on the same loop (``graph.build_nodes``), a goal is taken,
    accepted and started on one thread, with no executor wake-up and no hand-over
    between threads; its result and cancel requests are answered while it waits for a
    service (:class:`~suspension_tuning.nodes._service_calls.ServiceCaller`), or
    between its model runs.

    Parameters
    ----------
    owner : rclpy.node.Node
        The action server's node (for its logger; the server is removed from its
        waitables).
    server : rclpy.action.ActionServer
        The server, with synchronous callbacks.
    name : str
        The action's name, for log messages.
    loop : ServiceLoop
        The loop to be served by.
    """

    def __init__(self, owner: Node, server: Any, name: str, loop: ServiceLoop) -> None:
        self.owner = owner
        self.service = server  # what the loop waits on (wait_ready takes Waitables)
        self.service_name = f'action {name}'
        self.loop = loop
        owner.remove_waitable(server)
        loop.add(self)

    def _take_and_answer(self) -> None:
        """Take what is ready and run rclpy's handling of it (on the loop's thread)."""
        logger = self.owner.get_logger()
        try:
            data = self.service.take_data()
        except InvalidHandle:  # destroyed under the wait
            return
        except Exception as error:  # noqa: BLE001 - e.g. a request that does not convert
            logger.error(f'{self.service_name}: nothing taken: {error}')
            return
        handling = self.service.execute(data)
        try:
            handling.send(None)
        except StopIteration:  # done, in one step
            return
        except Exception as error:  # noqa: BLE001 - logged; the loop serves on
            logger.error(f'{self.service_name} failed: {type(error).__name__}: {error}')
            return
        handling.close()
        logger.error(f'{self.service_name}: a callback awaited something; not served '
                     'on the loop (its callbacks must be synchronous)')

    def destroy(self, timeout_s: float = 5.0) -> None:
        """Leave the loop and give the server back to its node.

        Back among the node's waitables, so that ``ActionServer.destroy`` (which removes
        it from there) can run afterwards.
        """
        self.loop.remove(self, timeout_s)
        self.owner.add_waitable(self.service)
