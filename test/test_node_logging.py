"""Per-run log lines without rclpy's caller lookup (suspension_tuning.nodes._logging)."""

import threading

import rclpy
from rcl_interfaces.msg import Log
from rclpy.logging import LoggingSeverity

from suspension_tuning.nodes import _logging


def test_an_info_line_reaches_rosout_with_its_caller_and_level(ros_context, executor):
    node = rclpy.create_node('talker', context=ros_context)
    listener = rclpy.create_node('listener', context=ros_context)
    received: list[Log] = []
    arrived = threading.Event()

    def on_log(msg: Log) -> None:
        if msg.name == 'talker':
            received.append(msg)
            arrived.set()

    listener.create_subscription(Log, '/rosout', on_log, 10)
    executor.add(node, listener)
    # Publisher and subscription must have matched before the line is sent.
    for _ in range(100):
        if node.count_subscribers('/rosout') >= 1:
            break
        threading.Event().wait(0.05)
    assert _logging.info(node, 'optimising ride with 2 variables')
    assert arrived.wait(10.0)
    line = received[0]
    assert line.msg == 'optimising ride with 2 variables'
    assert line.level == Log.INFO  # 20, rcl_interfaces/msg/Log
    assert line.function == 'test_an_info_line_reaches_rosout_with_its_caller_and_level'
    assert line.file.endswith('test_node_logging.py')


def test_a_line_below_the_loggers_level_is_dropped(ros_context):
    node = rclpy.create_node('quiet', context=ros_context)
    node.get_logger().set_level(LoggingSeverity.WARN)
    try:
        assert not _logging.info(node, 'not shown')
        assert _logging.log(node, LoggingSeverity.ERROR, 'shown')
    finally:
        node.destroy_node()
