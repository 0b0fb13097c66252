"""The ``main()`` of a node executable, in the Jazzy shape of ros2/demos."""

from __future__ import annotations

from collections.abc import Callable

import rclpy
from rclpy.exceptions import InvalidHandle
from rclpy.executors import (
    Executor,
    ExternalShutdownException,
    MultiThreadedExecutor,
    SingleThreadedExecutor,
)
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node


def spin_until_shutdown(executor: Executor,
                        until: Callable[[], bool] | None = None) -> None:
    """Spin until Ctrl-C or the context shuts down (or ``until()`` turns true).

    Ctrl-C normally raises KeyboardInterrupt here, or ExternalShutdownException once
    rclpy's signal handler has shut the context down.  When the interrupt lands in a
    ``__del__`` (e.g. of an rclpy Future) Python prints and drops it, the context is
    shut down all the same, and the next spin fails to build its wait set with an
    RCLError: that is a shutdown too, not a crash.  So is an InvalidHandle once the
    executor has been shut down from another thread (``SpinningGraph.shutdown``):
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
    """
    try:
        if until is None:
            executor.spin()
        else:
            while executor.context.ok() and not until():
                executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except _rclpy.RCLError:
        if executor.context.ok():
            raise
    except InvalidHandle:
        if not getattr(executor, '_is_shutdown', False):  # rclpy's flag, set first
            raise


def run_node(make_node: Callable[[], Node], args: list[str] | None = None,
             multithreaded: bool = True) -> None:
    """Initialise rclpy, spin one node until Ctrl-C or shutdown, then clean up.

    Parameters
    ----------
    make_node : callable
        Creates the node (after ``rclpy.init``, so ``--ros-args`` apply to it).
    args : list of str, optional
        Command-line arguments (``--ros-args ...``); default ``sys.argv``.
    multithreaded : bool
        A MultiThreadedExecutor, for nodes with callbacks that run long while other
        requests must still be answered; otherwise a SingleThreadedExecutor, the
        cheaper per callback.  (Service calls made from a callback take their own
        responses, ``_service_calls.ServiceCaller``, the hot services have threads of
        their own, ``_service_thread.py``, and the coordinator's goals run on goal
        threads: none of them needs this executor.)
    """
    rclpy.init(args=args)
    node = make_node()
    executor: Executor = MultiThreadedExecutor() if multithreaded else SingleThreadedExecutor()
    executor.add_node(node)
    try:
        spin_until_shutdown(executor)
    finally:
        node.destroy_node()
        executor.shutdown(timeout_sec=1.0)
        rclpy.try_shutdown()
