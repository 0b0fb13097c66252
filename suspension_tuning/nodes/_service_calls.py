"""Blocking service calls from worker threads, and a pool of simulation workers.

rclpy's ``Client.call()`` must not be used inside a callback (it may deadlock,
rclpy/client.py).  The coordinator and the gradient evaluator call services from
the thread of an action or service callback running on a MultiThreadedExecutor, so
they send with ``call_async`` and wait on a ``threading.Event`` set by the future's
done-callback, with a timeout; the executor's other threads deliver the response.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from suspension_tuning_interfaces.srv import EvaluateDesign


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


def call(node: Node, client: Any, request: Any, timeout_s: float,
         wait_for_service_s: float = 5.0) -> Any:
    """Call a service and wait for its response from a non-executor thread.

    Parameters
    ----------
    node : rclpy.node.Node
        Node owning the client (for logging).
    client : rclpy.client.Client
        Client, in a callback group that lets the response be delivered while this
        thread waits (e.g. ReentrantCallbackGroup on a MultiThreadedExecutor).
    request : object
        Service request.
    timeout_s : float
        Time to wait for the response, s.
    wait_for_service_s : float
        Time to wait for the service to appear, s.

    Returns
    -------
    object
        The response.

    Raises
    ------
    ServiceCallError
        Service unavailable, no response within ``timeout_s``, or service gone.
    """
    if not client.wait_for_service(timeout_sec=wait_for_service_s):
        raise ServiceCallError(f'service {client.srv_name} not available')
    done = threading.Event()
    future = client.call_async(request)
    future.add_done_callback(lambda _: done.set())
    deadline = time.monotonic() + timeout_s
    while not done.wait(0.1):
        if time.monotonic() > deadline:
            client.remove_pending_request(future)
            raise ServiceCallError(f'service {client.srv_name}: no response within {timeout_s} s')
        if not client.service_is_ready():
            client.remove_pending_request(future)
            raise ServiceCallError(f'service {client.srv_name} vanished while waiting')
    if future.exception() is not None:
        raise ServiceCallError(f'service {client.srv_name} failed: {future.exception()}')
    return future.result()


class SimulationPool:
    """Spreads batches of designs over several full-vehicle simulation workers.

    Several servers on one service name would all receive each request, so every
    worker has its own name (``/<worker>/evaluate``).  A batch is split into
    contiguous chunks, one per live worker, sent concurrently; a chunk whose worker
    fails (timeout, vanished) is sent again to another live worker, and the failed
    worker is not used again.  When no worker is left, :class:`ServiceCallError` says so.

    Parameters
    ----------
    node : rclpy.node.Node
        Node that owns the clients.
    workers : sequence of str
        Worker node names or namespaces, e.g. ``['/sim_0', '/sim_1']``.
    timeout_s : float
        Time one chunk may take before its worker is declared dead, s.
    """

    def __init__(self, node: Node, workers: Sequence[str], timeout_s: float) -> None:
        if not workers:
            raise ValueError('at least one simulation worker is needed')
        self.node = node
        self.timeout_s = timeout_s
        group = ReentrantCallbackGroup()
        self.clients = {name: node.create_client(EvaluateDesign,
                                                 f'{name.rstrip("/")}/evaluate',
                                                 callback_group=group)
                        for name in workers}
        self.alive = list(workers)
        self.calls = 0

    def evaluate(self, scenario: str, n_vars: int, designs: np.ndarray,
                 return_inputs: bool = False, publish_telemetry: bool = False
                 ) -> list[EvaluateDesign.Response]:
        """Evaluate designs (m, n_vars); return the chunk responses in design order.

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
            results: dict[int, Any] = {}
            threads = []
            for slot, (index, chunk) in enumerate(pending.items()):
                worker = self.alive[slot % len(self.alive)]
                request = EvaluateDesign.Request(
                    scenario=scenario, n_vars=n_vars,
                    designs=designs[chunk].ravel().tolist(),
                    publish_telemetry=publish_telemetry and index == 0,
                    return_inputs=return_inputs)
                thread = threading.Thread(target=self._send, daemon=True,
                                          args=(worker, request, index, results))
                threads.append(thread)
                thread.start()
            for thread in threads:
                thread.join()
            for index, (worker, outcome) in results.items():
                if isinstance(outcome, ServiceCallError):
                    self.node.get_logger().warning(
                        f'worker {worker} failed ({outcome}); retrying its designs elsewhere')
                    if worker in self.alive:
                        self.alive.remove(worker)
                    continue
                if not outcome.success:
                    raise ValueError(outcome.error)
                responses[index] = outcome
                del pending[index]
        return [responses[i] for i in sorted(responses)]

    def _send(self, worker: str, request: Any, index: int, results: dict) -> None:
        self.calls += 1
        try:
            results[index] = (worker, call(self.node, self.clients[worker], request,
                                           self.timeout_s))
        except ServiceCallError as error:
            results[index] = (worker, error)
