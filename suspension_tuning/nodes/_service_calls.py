"""Blocking service calls from callbacks, and a pool of simulation workers.

rclpy's ``Client.call()`` must not be used inside a callback (it may deadlock,
rclpy/client.py).  The coordinator and the gradient evaluator call services from an
action or service callback, so their clients sit on a private node that no executor
spins: the waiting thread takes the responses itself (:class:`ServiceCaller`), with
timeouts; the callback's own executor may then be single-threaded.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from contextlib import ExitStack
from typing import TYPE_CHECKING, Any

import numpy as np
import rclpy
from rclpy.exceptions import InvalidHandle
from rclpy.executors import SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.utilities import timeout_sec_to_nsec
from rclpy.waitable import NumberOfEntities, Waitable
from suspension_tuning_interfaces.srv import EvaluateDesign

if TYPE_CHECKING:
    from suspension_tuning.nodes._service_thread import ServiceLoop


def hidden_node(owner: Node, name: str, **node_options: Any) -> Node:
    """A node of ``owner``'s process for work beside the owner's executor.

    It lives in the owner's namespace and context and keeps ``name`` under a global
    ``-r __node:=...`` rename (which would otherwise make it a second node of the
    owner's name: duplicate parameter services, one rosout logger), through a
    node-local remap that takes precedence while topic and service remaps still apply.

    Parameters
    ----------
    owner : rclpy.node.Node
        The node the helper works for.
    name : str
        The helper node's name (``_name`` hides it from ``ros2 node list``).
    **node_options
        Further ``rclpy.create_node`` options (e.g. ``start_parameter_services``).
    """
    return rclpy.create_node(name, context=owner.context, namespace=owner.get_namespace(),
                             cli_args=['--ros-args', '-r', f'__node:={name}'], **node_options)


def helper_node(owner: Node, name: str, **node_options: Any
                ) -> tuple[Node, SingleThreadedExecutor]:
    """A :func:`hidden_node` with an executor of its own, spun by whoever waits.

    For work a callback must finish without its own executor's help (a step-locked
    closed loop): the waiting thread spins the helper's executor itself, as
    ``rclpy.spin_until_future_complete`` does.
    """
    node = hidden_node(owner, name, **node_options)
    executor = SingleThreadedExecutor(context=owner.context)
    executor.add_node(node)
    return node, executor


def wait_ready(context: Any, timeout_ns: int, clients: Sequence[Any] = (),
               services: Sequence[Any] = (), guards: Sequence[Any] = ()
               ) -> tuple[list[Any], list[Any]]:
    """Block on one wait set of these entities; return the ready clients and services.

    The loop of rclpy's own ``wait_for_message`` (``rclpy/wait_for_message.py``), for
    the clients and services of nodes that no executor spins.  An entity destroyed
    in the meantime is left out of the wait.

    Parameters
    ----------
    context : rclpy.context.Context
        Context of the entities.
    timeout_ns : int
        Longest wait, ns; -1 waits until something is ready.
    clients, guards : sequences
        rclpy clients and guard conditions to wait on.
    services : sequence
        rclpy services, and Waitables that serve requests (an action server), to wait
        on.  A ready Waitable has been asked ``is_ready`` (so its ``take_data`` takes
        what is in), as an executor does.
    """
    with ExitStack() as handles:
        live: dict[str, list[Any]] = {}
        waitables = [entity for entity in services if isinstance(entity, Waitable)]
        for kind, entities in (('client', clients), ('guard_condition', guards),
                               ('service', [s for s in services
                                            if not isinstance(s, Waitable)]),
                               ('waitable', waitables)):
            live[kind] = []
            for entity in entities:
                try:
                    # A Waitable is its own context manager (its handle's).
                    handles.enter_context(entity if kind == 'waitable' else entity.handle)
                except InvalidHandle:  # destroyed since: not waited on
                    continue
                live[kind].append(entity)
        handles.enter_context(context.handle)
        count = NumberOfEntities(0, len(live['guard_condition']), 0, len(live['client']),
                                 len(live['service']))
        for waitable in live['waitable']:
            count += waitable.get_num_entities()
        wait_set = _rclpy.WaitSet(count.num_subscriptions, count.num_guard_conditions,
                                  count.num_timers, count.num_clients, count.num_services,
                                  count.num_events, context.handle)
        wait_set.clear_entities()
        for client in live['client']:
            wait_set.add_client(client.handle)
        for service in live['service']:
            wait_set.add_service(service.handle)
        for guard in live['guard_condition']:
            wait_set.add_guard_condition(guard.handle)
        for waitable in live['waitable']:
            waitable.add_to_wait_set(wait_set)
        wait_set.wait(timeout_ns)
        ready = {kind: wait_set.get_ready_entities(kind) for kind in ('client', 'service')}
        return ([c for c in live['client'] if c.handle.pointer in ready['client']],
                [s for s in live['service'] if s.handle.pointer in ready['service']]
                + [w for w in live['waitable'] if w.is_ready(wait_set)])


class ServiceCallError(RuntimeError):
    """A service did not answer: not available, timed out, or vanished."""


def wait_future(future: Any, timeout_s: float | None = None) -> Any:
    """Wait for an rclpy future completed by an executor in another thread.

    Raises
    ------
    TimeoutError
        No result within ``timeout_s`` seconds (None waits for ever).
    """
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout_s):
        raise TimeoutError(f'no answer within {timeout_s} s')
    return future.result()


class ServiceCaller:
    """Service clients on a private node, whose responses the waiting thread takes.

    A node's service callback that calls another service must not wait for an
    executor to deliver the response from another thread: on a MultiThreadedExecutor
    that costs a hand-over between Python threads (a wake of the executor, a thread
    of its pool, then the waiting thread) for every response, about 2-3 ms, and on a
    SingleThreadedExecutor it deadlocks.  So the clients live on a hidden node of
    their own (``_<node>_calls``) that no executor spins; the calling thread waits on
    a wait set of its pending clients and takes the responses itself
    (:meth:`_take_responses`).  Callers on several threads take turns (a lock).

    A caller that waits on the thread of ``serve_loop`` (a callback or a job of that
    :class:`~suspension_tuning.nodes._service_thread.ServiceLoop`) answers the
    loop's requests while it waits: the loop cannot take them while its thread
    waits here, and a call to a service of the same loop is answered on this thread,
    through the middleware as any other call but with no thread to wake
    (``benchmarks/bench_graph_timeline.py``, ``call_overhead_ms``).

    Parameters
    ----------
    node : rclpy.node.Node
        The node on whose behalf the calls are made (name, namespace, context).
    serve_loop : ServiceLoop, optional
        The loop whose requests a wait on its thread answers.
    """

    def __init__(self, node: Node, serve_loop: ServiceLoop | None = None) -> None:
        self.owner = node
        self.serve_loop = serve_loop
        self.node = hidden_node(node, f'_{node.get_name()}_calls',
                                start_parameter_services=False, enable_rosout=False)
        # Re-entrant: a request answered inside a wait may call through this caller.
        self._lock = threading.RLock()
        self._answered: set[Any] = set()  # clients whose last call was answered

    def create_client(self, srv_type: Any, name: str) -> Any:
        """A client of service ``name`` (relative names resolve in the owner's namespace)."""
        return self.node.create_client(srv_type, name)

    def call(self, client: Any, request: Any, timeout_s: float,
             wait_for_service_s: float = 5.0) -> Any:
        """Call one service and return its response.

        Raises
        ------
        ServiceCallError
            Service unavailable, no response within ``timeout_s`` seconds, or service
            gone while waiting.
        """
        outcome = self.call_many([(client, request)], timeout_s, wait_for_service_s)[0]
        if isinstance(outcome, ServiceCallError):
            raise outcome
        return outcome

    def call_many(self, calls: Sequence[tuple[Any, Any]], timeout_s: float,
                  wait_for_service_s: float = 5.0) -> list[Any]:
        """Send several requests at once and wait for all of them.

        Parameters
        ----------
        calls : sequence of (client, request)
            Clients created by :meth:`create_client`, and their requests.
        timeout_s : float
            Time each request may take, s.
        wait_for_service_s : float
            Time to wait for a service to appear, s.

        Returns
        -------
        list
            Per call, in order: the response, or a :class:`ServiceCallError` saying
            why there is none (unavailable, timed out, vanished).
        """
        outcomes: list[Any] = [None] * len(calls)
        pending: dict[int, Any] = {}
        with self._lock:
            for i, (client, request) in enumerate(calls):
                # A server that answered the client's last call is taken to be there
                # still (a graph query costs ~40 us); one that has gone since is
                # noticed below, after a wait without news.
                if (client not in self._answered
                        and not client.wait_for_service(timeout_sec=wait_for_service_s)):
                    outcomes[i] = ServiceCallError(f'service {client.srv_name} not available')
                else:
                    pending[i] = client.call_async(request)
            deadline = time.monotonic() + timeout_s
            while pending:
                # A worker that vanishes is noticed within a second.  Shorter waits cost
                # the model: each wake-up of this thread takes the GIL from the thread
                # running the model in a burst of hand-overs of about 4 ms (measured
                # with 0.1 s waits: about 1,000 time slices per 0.7 s batch, and the
                # batch 50-70 ms slower than with no waiting thread).
                try:
                    news = self._take_responses([calls[i][0] for i in pending], 1.0)
                    shut_down = False
                except _rclpy.RCLError:
                    if self.node.context.ok():
                        raise
                    news, shut_down = False, True  # Ctrl-C or shutdown: no answer can come
                expired = time.monotonic() > deadline
                for i, future in list(pending.items()):
                    client = calls[i][0]
                    if future.done():
                        error = future.exception()
                        outcomes[i] = (ServiceCallError(f'service {client.srv_name} failed: '
                                                        f'{error}') if error is not None
                                       else future.result())
                    elif shut_down:
                        outcomes[i] = ServiceCallError(f'service {client.srv_name}: ROS shut '
                                                       'down while waiting')
                    elif expired:
                        outcomes[i] = ServiceCallError(f'service {client.srv_name}: no '
                                                       f'response within {timeout_s} s')
                    elif not news and not client.service_is_ready():
                        outcomes[i] = ServiceCallError(f'service {client.srv_name} vanished '
                                                       'while waiting')
                    else:
                        continue
                    if isinstance(outcomes[i], ServiceCallError):
                        self._answered.discard(client)
                    else:
                        self._answered.add(client)
                    if not future.done():
                        client.remove_pending_request(future)
                    del pending[i]
        return outcomes

    def _take_responses(self, clients: Sequence[Any], timeout_s: float) -> bool:
        """Wait until a response is in for one of ``clients`` (or the timeout), take it.

        Returns whether anything came in (a response, or a request answered).

        The private node holds nothing but these clients, so its wait needs none of
        the executor's machinery; an executor's ``spin_once`` (a new wait set built in
        Python from every entity of its nodes, a timer for the timeout, a task per
        response and one more for the future's done callback) cost about 0.4 ms per
        response.  Here: a wait set of the pending clients (:func:`wait_ready`), then
        ``take_response`` and the future of its sequence number, as the executor's
        ``_take_client`` does.  On the thread of :attr:`serve_loop`, the loop's
        requests that come in meanwhile are answered here too.
        """
        loop = self.serve_loop
        entries = loop.idle() if loop is not None and loop.on_thread() else []
        ready, requests = wait_ready(self.node.context, timeout_sec_to_nsec(timeout_s),
                                     clients=list(dict.fromkeys(clients)),
                                     services=[entry.service for entry in entries])
        served = [entry for entry in entries if entry.service in requests]
        for entry in served:
            loop.serve(entry)
        for client in ready:
            with client.handle:
                header, response = client.handle.take_response(client.srv_type.Response)
            if header is None:
                continue
            try:
                future = client.get_pending_request(header.request_id.sequence_number)
            except KeyError:  # given up on (timed out) before the answer came
                continue
            future.set_result(response)
        return bool(ready or served)

    def destroy(self) -> None:
        """Destroy the private node."""
        self.node.destroy_node()


class SimulationPool:
    """Spreads batches of designs over several full-vehicle simulation workers.

    Several servers on one service name would all receive each request, so every
    worker has its own name (``/<worker>/evaluate``).  A batch is split into
    contiguous chunks, one per live worker, sent concurrently; a chunk whose worker
    fails (timeout, vanished) is sent again to another live worker, and the failed
    worker is not used again.  When no worker is left, :class:`ServiceCallError` says so.

    Parameters
    ----------
    caller : ServiceCaller
        The calling node's private clients.
    workers : sequence of str
        Worker node names or namespaces, e.g. ``['/sim_0', '/sim_1']``.
    timeout_s : float
        Time one chunk may take before its worker is declared dead, s.
    """

    def __init__(self, caller: ServiceCaller, workers: Sequence[str], timeout_s: float) -> None:
        if not workers:
            raise ValueError('at least one simulation worker is needed')
        self.caller = caller
        self.timeout_s = timeout_s
        self.clients = {name: caller.create_client(EvaluateDesign,
                                                   f'{name.rstrip("/")}/evaluate')
                        for name in workers}
        self.alive = list(workers)
        self.calls = 0

    def evaluate(self, scenario: str, n_vars: int, designs: np.ndarray,
                 return_inputs: bool = False, publish_telemetry: bool = False,
                 integrator: str = '') -> list[EvaluateDesign.Response]:
        """Evaluate designs (m, n_vars); return the chunk responses in design order.

        ``integrator``: the full-model integrator ('' = each worker's parameter).

        Raises
        ------
        ValueError
            A worker rejected the request (its error text).
        ServiceCallError
            No live worker is left.
        """
        designs = np.atleast_2d(np.asarray(designs, dtype=float))
        chunks = np.array_split(np.arange(len(designs)), min(len(self.alive), len(designs)))
        pending = {i: chunk for i, chunk in enumerate(chunks) if chunk.size}
        responses: dict[int, EvaluateDesign.Response] = {}
        while pending:
            if not self.alive:
                raise ServiceCallError('no simulation worker left: every worker failed or '
                                       'timed out (' + ', '.join(self.clients) + ')')
            sent = []
            for slot, (index, chunk) in enumerate(pending.items()):
                worker = self.alive[slot % len(self.alive)]
                sent.append((index, worker, EvaluateDesign.Request(
                    scenario=scenario, n_vars=n_vars,
                    designs=designs[chunk].ravel().tolist(),
                    publish_telemetry=publish_telemetry and index == 0,
                    return_inputs=return_inputs, integrator=integrator)))
            self.calls += len(sent)
            outcomes = self.caller.call_many(
                [(self.clients[worker], request) for _, worker, request in sent],
                self.timeout_s)
            for (index, worker, _), outcome in zip(sent, outcomes):
                if isinstance(outcome, ServiceCallError):
                    self.caller.owner.get_logger().warning(
                        f'worker {worker} failed ({outcome}); retrying its designs elsewhere')
                    if worker in self.alive:
                        self.alive.remove(worker)
                    continue
                if not outcome.success:
                    raise ValueError(outcome.error)
                responses[index] = outcome
                del pending[index]
        return [responses[i] for i in sorted(responses)]
