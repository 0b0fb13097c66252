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

import numpy as np
import yaml
from rclpy.callback_groups import CallbackGroup
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_services_default,
)
from rclpy.service_introspection import ServiceIntrospectionState
from std_msgs.msg import String
from suspension_tuning_interfaces.srv import EvaluateDesign

from suspension_tuning.model_identity import ModelMismatchError, check_same

#: Longest wait between looks at a server that may have vanished, s.  Shorter waits
#: wake the waiting thread more often, and each wake-up takes the GIL from the thread
#: running a model (with 0.1 s waits a 0.7 s batch ran 50-70 ms slower).
POLL_S = 1.0
#: A worker's model description: a late subscriber still gets it.
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


def _description(text: str) -> dict[str, Any]:
    """A worker's ~/model message as a dict (a text that is no mapping: no fingerprint)."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError:
        data = None
    return data if isinstance(data, dict) else {'unreadable_description': text}


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


class SimulationPool:
    """Spreads batches of designs over several full-vehicle simulation workers.

    Several servers on one service name would all receive each request, so every
    worker has its own name (``/<worker>/evaluate``).  A batch is split into
    contiguous chunks, one per live worker, sent concurrently; a chunk whose worker
    fails (timeout, vanished) is sent again to another live worker, and the failed
    worker is not used again until :meth:`revive` finds its service up.  When no
    worker is left, :class:`ServiceCallError` says so.
    The pool keeps each worker's latched model description; :meth:`check_models` pins
    the one fingerprint of the live workers (or refuses a mix), and every answer after
    it must carry that fingerprint.

    Parameters
    ----------
    node : rclpy.node.Node
        The calling node.
    workers : sequence of str
        Worker node names or namespaces, e.g. ``['/sim_0', '/sim_1']``.
    timeout_s : float
        Time one chunk may take before its worker is declared dead, s.
    group : CallbackGroup
        Callback group of the clients (not one the caller holds).
    stopping : callable
        As for :func:`call_many`.
    """

    def __init__(self, node: Node, workers: Sequence[str], timeout_s: float,
                 group: CallbackGroup, stopping: Callable[[], bool] = lambda: False) -> None:
        if not workers:
            raise ValueError('at least one simulation worker is needed')
        self.node = node
        self.timeout_s = timeout_s
        self.stopping = stopping
        self.clients = {name: node.create_client(EvaluateDesign,
                                                 f'{name.rstrip("/")}/evaluate',
                                                 callback_group=group)
                        for name in workers}
        self.alive = list(workers)
        self.calls = 0
        # Each worker's model description (its latched ~/model, with the fingerprint),
        # and the fingerprint every answer must carry once check_models pinned it.
        self.models: dict[str, dict[str, Any]] = {}
        self.fingerprint = ''
        for name in workers:
            node.create_subscription(
                String, f'{name.rstrip("/")}/model',
                lambda msg, name=name: self.models.__setitem__(name, _description(msg.data)),
                LATCHED, callback_group=group)

    def check_models(self, wait_s: float = 5.0) -> str:
        """The fingerprint of the live workers' model, pinned for the answers that follow.

        Waits up to ``wait_s`` for each live worker's model description.  A worker not
        heard from whose service is not there either is dropped (as a dead one would
        be); every other worker must have described its model.

        Raises
        ------
        ModelMismatchError
            The workers run different models (the message names each and its
            fingerprint).
        ServiceCallError
            No live worker, or one that answers but has not described its model.
        """
        self.fingerprint = ''
        deadline = time.monotonic() + wait_s
        while (any(w not in self.models for w in self.alive) and time.monotonic() < deadline
               and not self.stopping()):
            time.sleep(0.02)  # the subscriptions are served by the node's executor
        for worker in [w for w in self.alive if w not in self.models]:
            if self.clients[worker].service_is_ready():
                raise ServiceCallError(f'worker {worker} serves evaluate but has published no '
                                       f'model description (~/model) within {wait_s} s')
            self.node.get_logger().warning(f'worker {worker} is not running (no model '
                                           'description, no service): not used')
            self.alive.remove(worker)
        if not self.alive:
            raise ServiceCallError('no simulation worker is running (' +
                                   ', '.join(self.clients) + ')')
        self.fingerprint = check_same({w: str(self.models[w].get('fingerprint', 'none'))
                                       for w in self.alive})
        return self.fingerprint

    def revive(self) -> None:
        """Use again the failed workers whose service is up (e.g. restarted) now."""
        self.alive = [name for name, client in self.clients.items()
                      if name in self.alive or client.service_is_ready()]

    def evaluate(self, scenario: str, n_vars: int, designs: np.ndarray,
                 return_inputs: bool = False, publish_telemetry: bool = False,
                 integrator: str = '', road: str = '') -> list[EvaluateDesign.Response]:
        """Evaluate designs (m, n_vars); return the chunk responses in design order.

        ``integrator``: the full-model integrator ('' = each worker's parameter);
        ``road``: the ride road ('' = each worker's configured one).

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
                    return_inputs=return_inputs, integrator=integrator, road=road)))
            self.calls += len(sent)
            outcomes = call_many(self.node, [(self.clients[worker], request)
                                             for _, worker, request in sent],
                                 self.timeout_s, stopping=self.stopping)
            for (index, worker, _), outcome in zip(sent, outcomes):
                if isinstance(outcome, ServiceCallError):
                    if self.stopping() or not self.node.context.ok():
                        raise outcome
                    self.node.get_logger().warning(
                        f'worker {worker} failed ({outcome}); retrying its designs elsewhere')
                    if worker in self.alive:
                        self.alive.remove(worker)
                    continue
                if not outcome.success:
                    raise ValueError(outcome.error)
                if self.fingerprint and outcome.model_fingerprint != self.fingerprint:
                    raise ModelMismatchError(
                        f'worker {worker} answered from model {outcome.model_fingerprint}, '
                        f'but this run uses model {self.fingerprint}: a worker restarted '
                        'with another model, FMU, mapping or configuration')
                responses[index] = outcome
                del pending[index]
        return [responses[i] for i in sorted(responses)]
