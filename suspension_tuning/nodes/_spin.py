"""The ``main()`` of a node executable, in the Jazzy shape of ros2/demos."""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import rclpy
from rclpy.executors import (
    Executor,
    ExternalShutdownException,
    SingleThreadedExecutor,
)
from rclpy.node import Node


def executor_for(node: Node) -> Executor:
    """A new executor of the kind ``node`` asks for (its class attribute ``EXECUTOR``).

    Nodes whose callbacks wait for other callbacks (a service call's response, a
    valve state) name ``MultiThreadedExecutor``; the others, and any node without
    the attribute, get a SingleThreadedExecutor, the cheaper per callback.
    """
    return getattr(node, 'EXECUTOR', SingleThreadedExecutor)(context=node.context)


def spin_until_shutdown(executor: Executor, until: Callable[[], bool] | None = None,
                        stopped: Callable[[], bool] | None = None) -> None:
    """Spin until Ctrl-C or the context shuts down (or ``until()`` turns true).

    Ctrl-C normally raises KeyboardInterrupt here, or ExternalShutdownException once
    rclpy's signal handler has shut the context down.  When the interrupt lands in a
    ``__del__`` (e.g. of an rclpy Future) Python prints and drops it, the context is
    shut down all the same, and the next spin fails to build its wait set with a
    RuntimeError: that is a shutdown too, not a crash.  So is a RuntimeError once
    the executor has been shut down from another thread (``stopped()`` says so):
    rclpy's ``Executor.shutdown`` destroys the executor's guard condition without
    waiting for the spin's tasks, and a task that is still running triggers it
    (ros2/rclpy#968, open; Jazzy).

    Parameters
    ----------
    executor : rclpy.executors.Executor
        The executor to spin.
    until : callable, optional
        Checked every 0.1 s; spinning stops when it returns True (e.g. a node's work
        is done).  Without it the executor spins until shutdown.
    stopped : callable, optional
        True once whoever owns the executor has shut it down (``SpinningGraph``).
    """
    try:
        if until is None:
            executor.spin()
        else:
            while executor.context.ok() and not until():
                executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RuntimeError:  # rclpy's RCLError and InvalidHandle
        if executor.context.ok() and not (stopped is not None and stopped()):
            raise


#: Longest wait for rclpy's signal handler to shut a context down after Ctrl-C, s.  Its
#: thread does so within microseconds of the signal; seconds cover a loaded machine.
SIGNAL_SETTLE_S = 5.0


def settle_signal(context: Any = None, timeout_s: float = SIGNAL_SETTLE_S) -> None:
    """After a KeyboardInterrupt: wait until rclpy's signal handler has shut ``context`` down.

    rclpy handles SIGINT in two steps: its C handler calls Python's (which raises
    KeyboardInterrupt in the main thread) and wakes a thread of its own, which then
    triggers every executor's SIGINT guard condition through raw pointers and, after
    that, shuts the contexts down.  An executor shut down (or garbage-collected) in
    between unregisters and frees its guard condition while that thread may still
    trigger it: a use after free, SIGSEGV in ``__rmw_trigger_guard_condition``
    (rmw_fastrtps_shared_cpp).  Once the context is no longer ok, that thread is done
    with the guard conditions, and executors can go.

    Returns at once when rclpy's SIGINT handler is not installed (the interrupt came
    from Python alone, nothing shuts the context down), and after ``timeout_s`` at most.

    Parameters
    ----------
    context : rclpy.context.Context, optional
        The context the handler shuts down (default: rclpy's default context).
    timeout_s : float
        Longest wait, s.
    """
    from rclpy.signals import SignalHandlerOptions, get_current_signal_handlers_options
    from rclpy.utilities import get_default_context

    options = get_current_signal_handlers_options()
    if options not in (SignalHandlerOptions.SIGINT, SignalHandlerOptions.ALL):
        return
    context = context or get_default_context()
    deadline = time.monotonic() + timeout_s
    while context.ok() and time.monotonic() < deadline:
        time.sleep(0.01)


def end_rclpy() -> None:
    """Shut rclpy's default context down and end its signal handler's thread.

    ``rclpy.try_shutdown`` leaves rclpy's signal handling thread running; a process that
    ends while that thread is still at work after a signal (it shuts the contexts down)
    dies in Python's finalisation ("terminate called without an active exception",
    SIGABRT).  Uninstalling the handlers joins the thread.
    """
    from rclpy.signals import uninstall_signal_handlers

    rclpy.try_shutdown()
    uninstall_signal_handlers()


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


class SpinningGraph:
    """The graph's nodes spinning in background threads, one executor per node.

    Each node gets the executor it asks for (``nodes._spin.executor_for``):
    multi-threaded for the nodes whose callbacks wait for a response (coordinator,
    gradient evaluator, simulation workers), single-threaded for the others.  One
    executor per node keeps each wait set small, and a telemetry burst for the
    recorder or the step-locked valve controller from waiting behind other nodes'
    callbacks.  :meth:`shutdown` stops the executors, joins the threads and destroys
    the nodes (the recorder finalises its bag).
    """

    def __init__(self, nodes: list[Node], extra: list[Node] = ()) -> None:
        self.nodes = [*nodes, *extra]
        self.stopped = False
        self.executors: list[Executor] = []
        for node in self.nodes:
            executor = executor_for(node)
            executor.add_node(node)
            self.executors.append(executor)
        #: Set when an executor's spin has returned (``wait`` has why not Thread.join).
        self.spun = [threading.Event() for _ in self.executors]
        self.threads = [threading.Thread(target=self._spin, args=(executor, done), daemon=True)
                        for executor, done in zip(self.executors, self.spun)]
        for thread in self.threads:
            thread.start()

    def _stopped(self) -> bool:
        return self.stopped

    def _spin(self, executor: Executor, done: threading.Event) -> None:
        try:
            spin_until_shutdown(executor, None, self._stopped)
        finally:
            done.set()

    def wait(self, until: Callable[[], bool] | None = None) -> None:
        """Block until the executors stop, the nodes' context shuts down or ``until()``.

        Ctrl-C raises KeyboardInterrupt here.  SIGTERM (and a Ctrl-C whose
        KeyboardInterrupt Python dropped in a ``__del__``) only shuts the context down:
        rclpy's signal handler triggers the executors' guard conditions *before* it
        shuts the contexts down, so an executor woken by that trigger sees its context
        still up and waits again, and nothing wakes it after the shutdown (rclpy calls a
        context's ``on_shutdown`` callbacks only when Python shuts it down).  Hence this
        returns on the context's state, not on the threads alone; :meth:`shutdown` then
        wakes and stops the executors.

        It waits on events of its own, not in ``Thread.join`` (nor ``is_alive``): a
        KeyboardInterrupt raised in there while the thread runs makes CPython 3.11
        release the thread's own state lock and mark it stopped (the bpo-45274
        handler), so that every later join returns at once with the executor still
        spinning; the nodes were then destroyed under it, and the process aborted at
        exit ("terminate called without an active exception") as that thread woke.

        Parameters
        ----------
        until : callable, optional
            Looked at every 0.2 s: returns when it is true (a node asks to be made
            again, :class:`~suspension_tuning.nodes._pause.PauseWatch`).
        """
        contexts = {executor.context for executor in self.executors}
        while not all(done.is_set() for done in self.spun):
            if not all(context.ok() for context in contexts) or (until is not None
                                                                 and until()):
                return
            next(done for done in self.spun if not done.is_set()).wait(0.2)

    def shutdown(self, interrupted: bool = False) -> None:
        """Stop spinning and destroy the nodes.

        Parameters
        ----------
        interrupted : bool
            Called on a KeyboardInterrupt (Ctrl-C): first wait until rclpy's signal
            handler has shut the context down (:func:`~suspension_tuning.nodes._spin.
            settle_signal`), as destroying an executor frees its guard conditions that
            the handler's thread may still be triggering.
        """
        if interrupted:
            settle_signal(self.executors[0].context if self.executors else None)
        self.stopped = True
        for executor in self.executors:
            executor.shutdown(timeout_sec=10.0)
        deadline = time.monotonic() + 10.0
        for done in self.spun:
            done.wait(max(0.0, deadline - time.monotonic()))
        for node in reversed(self.nodes):
            node.destroy_node()


def changeable_parameters(node: Node) -> list[Any]:
    """The node's parameters that may change while it runs (not read-only), as set now."""
    names = list(node.list_parameters([], 0).names)  # depth 0: every parameter
    return [parameter for parameter, descriptor
            in zip(node.get_parameters(names), node.describe_parameters(names))
            if not descriptor.read_only]


def kept_parameters(node: Node, saved: list[Any]) -> list[str]:
    """Set the ``saved`` values (:func:`changeable_parameters`) that differ on ``node``.

    A node made again keeps what ``ros2 param set`` changed on its predecessor; a
    value it refuses now stays as made, with a warning.  Returns the names set.
    """
    changed = [p for p in saved
               if node.has_parameter(p.name) and node.get_parameter(p.name).value != p.value]
    done = []
    for parameter, result in zip(changed, node.set_parameters(changed)):
        if result.successful:
            done.append(parameter.name)
        else:
            node.get_logger().warning(f'parameter {parameter.name} not kept: {result.reason}')
    if done:
        node.get_logger().info('kept the parameters set while it ran: ' + ', '.join(
            f'{p.name}={p.value!r}' for p in changed if p.name in done))
    return done


def made_or_stopped(make: Callable[[], Any], errors: tuple[type[Exception], ...],
                    who: Callable[[Exception], str]) -> Any:
    """``make()`` (nodes, after ``rclpy.init``), or None when a signal stopped it.

    An error of ``errors`` (a parameter, configuration or FMU set-up that cannot be used)
    ends the process with one line, ``<who(error)>: not started: <error>``, and exit
    code 2.  Ctrl-C or SIGTERM while it runs (the nodes made are then gone with the
    shut-down context) ends rclpy and returns None.
    """
    try:
        return make()
    except errors as error:
        rclpy.try_shutdown()
        print(f'{who(error)}: not started: {error}', file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:  # Ctrl-C while they are made
        settle_signal()
        end_rclpy()
        return None
    except Exception:
        if rclpy.ok():
            raise
        end_rclpy()  # SIGTERM while they are made: one failed on the shut-down context
        return None


def run_node(make_node: Callable[[], Node], args: list[str] | None = None, *,
             name: str | None = None, rename: bool = False,
             renew_after_pause: bool = False) -> None:
    """Initialise rclpy, spin one node until Ctrl-C or shutdown, then clean up.

    Parameters
    ----------
    make_node : callable
        Creates the node (after ``rclpy.init``, so ``--ros-args`` apply to it).  It
        is spun by :func:`executor_for` the node.
    args : list of str, optional
        Command-line arguments (``--ros-args ...``); default ``sys.argv``.
    name : str, optional
        The node's name as ``make_node`` creates it (before remapping).  With it, the
        node is not created when another node of its fully-qualified name runs on the
        domain (:mod:`suspension_tuning.nodes._unique`, a discovery wait of up to 3.5 s);
        the process says so in one line and exits with code 2.
    rename : bool
        The refusal also suggests another node name (a simulation worker).
    renew_after_pause : bool
        A node with a ``pause_watch`` (:class:`~suspension_tuning.nodes._pause.
        PauseWatch`) is made again, in a new context (a new DDS participant), after a
        pause of the process longer than the watch's bound: its peers then find it as
        they find a process restarted under its name.  The pause's work in progress
        ends first (the executor's shutdown waits for its callbacks, up to 10 s); the
        parameters set while it ran (``ros2 param set``) are set on the new node too.

    A parameter value the node cannot use (:class:`~suspension_tuning.nodes._parameters.
    ParameterError`) or a configuration file it cannot use (:class:`~suspension_tuning.
    config_check.ConfigError`) ends the process with its one-line message and exit code 2.
    """
    from suspension_tuning.config_check import ConfigError, check_params_files
    from suspension_tuning.nodes._parameters import ParameterError
    from suspension_tuning.nodes._unique import require_unique, start_check

    try:  # before rcl parses them: a syntax error there ends in its traceback
        check_params_files(sys.argv if args is None else list(args))
    except ConfigError as error:
        print(f'{name or "node"}: not started: {error}', file=sys.stderr)
        sys.exit(2)
    rclpy.init(args=args)
    if name is not None and not require_unique(name, start_check(name, [name]), rename):
        return  # Ctrl-C or SIGTERM during the check
    kept: list[Any] = []  # parameters set while the node ran, for its renewal
    def made() -> Node:
        node = make_node()
        if kept:
            kept_parameters(node, kept)
        return node

    while True:
        node = made_or_stopped(made, (ParameterError, ConfigError),
                               lambda _error: name or 'node')
        if node is None:
            return
        watch = getattr(node, 'pause_watch', None) if renew_after_pause else None
        if watch is not None:
            watch.renew = True
        # The node spins in a thread of its own, the main thread waits for Ctrl-C or for
        # the context to shut down (SIGTERM), as in ``graph`` (SpinningGraph has why).
        spinning = SpinningGraph([node])
        interrupted = renewing = False
        try:
            spinning.wait(until=None if watch is None else watch.renewal_due.is_set)
            renewing = watch is not None and watch.renewal_due.is_set() and rclpy.ok()
            if renewing:
                kept = changeable_parameters(node)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            spinning.shutdown(interrupted)
            end_rclpy()  # the participant goes: its peers are told it left
        if not renewing:
            return
        try:
            rclpy.init(args=args)  # a new default context: a new participant, same name
        except KeyboardInterrupt:  # Ctrl-C between the two contexts
            end_rclpy()
            return
