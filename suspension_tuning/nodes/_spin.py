"""The ``main()`` of a node executable, in the Jazzy shape of ros2/demos."""

from __future__ import annotations

import sys
import threading
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


def run_node(make_node: Callable[[], Node], args: list[str] | None = None, *,
             name: str | None = None, rename: bool = False) -> None:
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
    try:
        node = make_node()
    except (ParameterError, ConfigError) as error:
        rclpy.try_shutdown()
        print(f'{name or "node"}: not started: {error}', file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:  # Ctrl-C while the node is made
        rclpy.try_shutdown()
        return
    executor = executor_for(node)
    executor.add_node(node)
    try:
        spin_until_shutdown(executor)
    finally:
        node.destroy_node()
        executor.shutdown(timeout_sec=1.0)
        rclpy.try_shutdown()
