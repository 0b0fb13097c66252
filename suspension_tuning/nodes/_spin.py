"""The ``main()`` of a node executable, in the Jazzy shape of ros2/demos."""

from __future__ import annotations

from collections.abc import Callable

import rclpy
from rclpy.executors import (
    Executor,
    ExternalShutdownException,
    MultiThreadedExecutor,
    SingleThreadedExecutor,
)
from rclpy.node import Node


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
        A MultiThreadedExecutor, for nodes whose callbacks wait on other callbacks
        (a service callback that calls a service or waits for a topic); otherwise a
        SingleThreadedExecutor, the cheaper per callback.
    """
    rclpy.init(args=args)
    node = make_node()
    executor: Executor = MultiThreadedExecutor() if multithreaded else SingleThreadedExecutor()
    executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        executor.shutdown(timeout_sec=1.0)
        rclpy.try_shutdown()
