"""Log a node's per-run messages without rclpy's caller lookup.

rclpy's ``RcutilsLogger.log`` identifies its caller with ``inspect.getframeinfo``,
which reads the source file and searches ``sys.modules`` for the frame's module:
about 1 ms per message here (``benchmarks/bench_graph.py`` measured 1.06 ms for the
coordinator's "optimising ..." line, a tenth of the graph's own cost of a run; the
same cost is reported in rclpy issue #775 and worked around in synchros2 PR #84).
:func:`info` hands the message to rcutils as rclpy does (console, ``/rosout``, log
file, and the logger's level), with the caller's function, file and line read from
its frame directly.  rclpy's logging filters (``once``, ``throttle_duration_sec``)
are not offered.
"""

from __future__ import annotations

import os
import sys

from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.logging import LoggingSeverity
from rclpy.node import Node


def log(node: Node, severity: LoggingSeverity, message: str, depth: int = 1) -> bool:
    """Log ``message`` on ``node``'s logger; False when its level filters it out.

    Parameters
    ----------
    node : rclpy.node.Node
        Whose logger.
    severity : LoggingSeverity
        Level of the message.
    message : str
        The text.
    depth : int
        Frames above this function's caller to name as the message's origin.
    """
    logger = node.get_logger()
    if not logger.is_enabled_for(severity):
        return False
    frame = sys._getframe(depth)
    code = frame.f_code
    _rclpy.rclpy_logging_rcutils_log(severity, logger.name, message, code.co_name,
                                     os.path.abspath(code.co_filename), frame.f_lineno)
    return True


def info(node: Node, message: str) -> bool:
    """Log ``message`` at INFO on ``node``'s logger (see :func:`log`)."""
    return log(node, LoggingSeverity.INFO, message, depth=2)
