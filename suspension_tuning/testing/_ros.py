"""Isolated rclpy contexts, spinning executors and waiting with a timeout.

Only rclpy's public API: ``Context``, ``rclpy.init(context=..., domain_id=...)``,
executors spun with ``spin_once``, ``Client.call_async``, ``ActionClient`` and
futures.
"""

from __future__ import annotations

import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from typing import Any

import rclpy
from rclpy.action import ActionClient
from rclpy.client import Client
from rclpy.context import Context
from rclpy.executors import (
    Executor,
    ExternalShutdownException,
    MultiThreadedExecutor,
    SingleThreadedExecutor,
)
from rclpy.node import Node
from rclpy.task import Future

from suspension_tuning.testing._environment import (
    assert_loopback,
    loopback_environment,
    reserved_domain,
)

#: Longest wait for an answer unless told otherwise, s: a guard against a hang, long
#: enough for an optimisation through the graph on a loaded two-core machine.
DEFAULT_TIMEOUT_S = 300.0
#: Longest wait for a service or action server to be discovered, s.
DEFAULT_SERVER_TIMEOUT_S = 10.0
#: Period at which a spinning executor looks whether it is to stop, s.
SPIN_PERIOD_S = 0.1


class RosTimeoutError(TimeoutError):
    """A service, an action or a future did not answer in time (the message names it)."""


class GoalRejectedError(RuntimeError):
    """An action server rejected a goal."""


class CallbackError(RuntimeError):
    """Callbacks raised while an executor of the kit was spinning them."""


def interface_name(interface: type) -> str:
    """``package/srv/Name`` of a generated message, service or action class."""
    module = interface.__module__.split('.')
    kind = module[1] if len(module) > 1 else '?'
    return f'{module[0]}/{kind}/{interface.__name__}'


@contextmanager
def isolated_context(domain_id: int | None = None) -> Iterator[Context]:
    """An initialised rclpy context of its own, on loopback, shut down afterwards.

    ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and ``ROS_DOMAIN_ID`` are set while
    the block runs (and restored afterwards); the context is shut down and destroyed
    also when the block raises.

    Parameters
    ----------
    domain_id : int, optional
        The ROS domain, used as given (to join a graph of another process, say).  By
        default the process's reserved domain (:func:`reserved_domain`): a pytest
        session's, else a free one of 10..99, reserved on the machine while the block
        runs; every context of the process without a domain id shares it.

    Raises
    ------
    DomainInUseError
        Without ``domain_id``, if no domain of 10..99 is free on the machine.

    Examples
    --------
    >>> with isolated_context() as context:                         # doctest: +SKIP
    ...     node = rclpy.create_node('probe', context=context)
    """
    with ExitStack() as stack:
        domain = (stack.enter_context(reserved_domain()) if domain_id is None
                  else int(domain_id))
        stack.enter_context(loopback_environment(domain))
        assert_loopback(domain)
        context = Context()
        rclpy.init(context=context, domain_id=domain)
        try:
            yield context
        finally:
            rclpy.try_shutdown(context=context)
            context.destroy()


class SpinningExecutor:
    """An executor spinning its nodes in a background thread until :meth:`shutdown`.

    The thread calls ``spin_once`` until it is told to stop or the context shuts
    down; :meth:`stop` joins it before shutting the executor down, so that no
    callback is started on an executor being shut down.  A callback that raises is
    printed to stderr, kept in :attr:`errors` and spinning goes on; the fixtures and
    context managers of the kit raise :class:`CallbackError` at the end of a test
    that had any.

    Parameters
    ----------
    context : rclpy.context.Context
        The context of the executor and its nodes.
    num_threads : int
        Threads of a ``MultiThreadedExecutor``; 1 gives a ``SingleThreadedExecutor``.
    name : str
        Name of the spinning thread (seen in tracebacks).
    """

    def __init__(self, context: Context, num_threads: int = 4,
                 name: str = 'ros_executor') -> None:
        self.context = context
        self.executor: Executor = (
            SingleThreadedExecutor(context=context) if num_threads == 1
            else MultiThreadedExecutor(num_threads=num_threads, context=context))
        self.nodes: list[Node] = []
        self.errors: list[BaseException] = []
        self._stopping = threading.Event()
        self._laps = 0
        self._lap = threading.Condition()
        self._thread = threading.Thread(target=self._spin, name=name, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not self._stopping.is_set() and self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=SPIN_PERIOD_S)
            except ExternalShutdownException:
                return
            except Exception as error:  # noqa: BLE001 - reported, and spinning goes on
                if self._stopping.is_set() or not self.context.ok():
                    return  # the executor or the context is going away under the wait
                self.errors.append(error)
                print(f'{self._thread.name}: a callback raised:', file=sys.stderr)
                traceback.print_exception(error, file=sys.stderr)
            with self._lap:
                self._laps += 1
                self._lap.notify_all()

    def add(self, *nodes: Node) -> None:
        """Spin these nodes too; :meth:`shutdown` destroys them."""
        for node in nodes:
            self.executor.add_node(node)
            self.nodes.append(node)

    def remove(self, node: Node, timeout_s: float = 10.0) -> None:
        """Stop spinning ``node`` (not destroyed): its entities may be destroyed after.

        Returns once the spinning thread has spun three times since, so that no wait
        set being built still holds one of its entities (destroying a service or
        action server under a running spin fails that spin in rclpy: "pointer is
        invalid").  Callbacks of the node already running go on to their end.
        """
        self.executor.remove_node(node)
        if node in self.nodes:
            self.nodes.remove(node)
        with self._lap:
            until = self._laps + 3
            self.executor.wake()
            self._lap.wait_for(lambda: self._laps >= until or not self._thread.is_alive(),
                               timeout_s)

    def stop(self, timeout_s: float = 10.0) -> None:
        """Stop spinning: join the thread, then shut the executor down."""
        self._stopping.set()
        self.executor.wake()
        self._thread.join(timeout=timeout_s)
        self.executor.shutdown(timeout_sec=timeout_s)

    def shutdown(self) -> None:
        """:meth:`stop`, then destroy the nodes (last added first)."""
        self.stop()
        for node in reversed(self.nodes):
            node.destroy_node()
        self.nodes.clear()


def raise_callback_errors(errors: list[BaseException]) -> None:
    """Raise :class:`CallbackError` listing ``errors`` (from the executors), if any."""
    if errors:
        listed = '; '.join(f'{type(e).__name__}: {e}' for e in errors[:5])
        more = f' (and {len(errors) - 5} more)' if len(errors) > 5 else ''
        raise CallbackError(f'{len(errors)} callback(s) raised while spinning: {listed}{more}'
                            ' (tracebacks on stderr)') from errors[0]


@contextmanager
def spinning_executor(context: Context, num_threads: int = 4) -> Iterator[SpinningExecutor]:
    """A :class:`SpinningExecutor` on ``context``; its nodes destroyed afterwards.

    Raises
    ------
    CallbackError
        After the block, if a callback raised while spinning (and the block did not).
    """
    spinning = SpinningExecutor(context, num_threads)
    try:
        yield spinning
    finally:
        spinning.shutdown()
    raise_callback_errors(spinning.errors)


def wait_for_future(future: Future, timeout_s: float = DEFAULT_TIMEOUT_S,
                    what: str = 'the future') -> Any:
    """The result of ``future`` once an executor completes it (raises its exception).

    The future's node must be spun by another thread (:class:`SpinningExecutor`).

    Raises
    ------
    RosTimeoutError
        If the future is not done within ``timeout_s`` (the message names ``what``).
    RuntimeError
        If the future was cancelled.
    """
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not (future.done() or done.wait(timeout_s)):
        raise RosTimeoutError(f'{what}: no answer within {timeout_s:g} s')
    if future.cancelled():
        raise RuntimeError(f'{what} was cancelled')
    return future.result()


def wait_until(predicate: Callable[[], bool], timeout_s: float = 15.0,
               period_s: float = 0.05) -> bool:
    """Poll ``predicate`` until it holds or ``timeout_s`` passes; its last value."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(period_s)
    return bool(predicate())


def call_service(client: Client, request: Any, timeout_s: float = DEFAULT_TIMEOUT_S,
                 server_timeout_s: float = DEFAULT_SERVER_TIMEOUT_S) -> Any:
    """Call a service through ``client`` and return its response.

    Parameters
    ----------
    client : rclpy.client.Client
        A client on a node that is spinning (e.g. on a :class:`SpinningExecutor`).
    request : the service's Request
        The request.
    timeout_s : float
        Longest wait for the response, s.
    server_timeout_s : float
        Longest wait for the service to be discovered, s.

    Raises
    ------
    RosTimeoutError
        If the service is not found or does not answer in time; the message names
        the service and its type.
    """
    what = f'service {client.srv_name} ({interface_name(client.srv_type)})'
    if not client.wait_for_service(timeout_sec=server_timeout_s):
        raise RosTimeoutError(f'{what}: not available after {server_timeout_s:g} s')
    future = client.call_async(request)
    try:
        return wait_for_future(future, timeout_s, what)
    except RosTimeoutError:
        client.remove_pending_request(future)
        raise


@dataclass
class GoalOutcome:
    """How an action goal ended: its final status, result and the feedback received."""

    status: int
    result: Any
    feedback: list[Any] = field(default_factory=list)


def send_goal(client: ActionClient, goal: Any, timeout_s: float = DEFAULT_TIMEOUT_S,
              feedback_callback: Callable[[Any], None] | None = None,
              server_timeout_s: float = DEFAULT_SERVER_TIMEOUT_S,
              action_name: str = '') -> GoalOutcome:
    """Send a goal, wait for its result and return how it ended.

    Parameters
    ----------
    client : rclpy.action.ActionClient
        A client on a node that is spinning.
    goal : the action's Goal
        The goal.
    timeout_s : float
        Longest wait for the goal to be accepted and then for its result, s.  On a
        timeout the goal is cancelled (so that the server is free for the next one).
    feedback_callback : callable, optional
        Called with each feedback message (``feedback.feedback``), as it arrives.
    server_timeout_s : float
        Longest wait for the action server to be discovered, s.
    action_name : str
        The action's name for messages (rclpy's ActionClient does not say it).

    Raises
    ------
    RosTimeoutError
        If the server is not found, or the goal is not answered in time; the message
        names the action and its type.
    GoalRejectedError
        If the server rejected the goal.
    """
    action_type = interface_name(type(goal)).removesuffix('_Goal')
    what = f'action {action_name or "(unnamed)"} ({action_type})'
    if not client.wait_for_server(timeout_sec=server_timeout_s):
        raise RosTimeoutError(f'{what}: no server after {server_timeout_s:g} s')
    feedback: list[Any] = []

    def on_feedback(message: Any) -> None:
        feedback.append(message.feedback)
        if feedback_callback is not None:
            feedback_callback(message.feedback)

    handle = wait_for_future(client.send_goal_async(goal, feedback_callback=on_feedback),
                             timeout_s, f'{what}: goal')
    if not handle.accepted:
        raise GoalRejectedError(f'{what}: the goal was rejected')
    try:
        response = wait_for_future(handle.get_result_async(), timeout_s, f'{what}: result')
    except RosTimeoutError:
        try:
            wait_for_future(handle.cancel_goal_async(), 5.0, f'{what}: cancel')
        except (RosTimeoutError, RuntimeError):
            pass  # the timeout is the error to report
        raise
    return GoalOutcome(status=int(response.status), result=response.result, feedback=feedback)
