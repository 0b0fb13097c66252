"""How a node's executor stops (suspension_tuning.nodes._spin.spin_until_shutdown)."""

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor

from suspension_tuning.nodes._spin import spin_until_shutdown


class WaitSetError(RuntimeError):
    """Stands for rclpy's RCLError (a RuntimeError) of a wait set on a dead context."""


def _executor_failing_with_rcl_error(shut_down_first: bool):
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)

    def spin():
        # What a Ctrl-C swallowed by a __del__ leaves behind: rclpy's signal handler
        # has shut the context down, and the next wait set cannot be built.
        if shut_down_first:
            context.shutdown()
        raise WaitSetError('failed to initialize wait set: the given context is not valid')

    executor.spin = spin
    return context, executor


def test_a_wait_set_error_after_the_context_shut_down_is_a_clean_stop():
    context, executor = _executor_failing_with_rcl_error(shut_down_first=True)
    spin_until_shutdown(executor)  # returns: no exception escapes
    assert not context.ok()


def test_a_wait_set_error_while_the_context_is_up_is_raised():
    context, executor = _executor_failing_with_rcl_error(shut_down_first=False)
    try:
        with pytest.raises(WaitSetError):
            spin_until_shutdown(executor)
    finally:
        context.shutdown()


def test_spinning_until_done_stops_when_the_condition_holds_or_the_context_goes():
    context, executor = _executor_failing_with_rcl_error(shut_down_first=True)
    spins = []

    def spin_once(timeout_sec=None):
        spins.append(timeout_sec)
        if len(spins) == 3:  # the third wait meets a context shut down under it
            context.shutdown()
            raise WaitSetError('failed to initialize wait set')

    executor.spin_once = spin_once
    spin_until_shutdown(executor, until=lambda: False)
    assert spins == [0.1, 0.1, 0.1]
    context, executor = _executor_failing_with_rcl_error(shut_down_first=False)
    executor.spin_once = lambda timeout_sec=None: pytest.fail('spun although done')
    try:
        spin_until_shutdown(executor, until=lambda: True)  # done already: returns
        assert context.ok()
    finally:
        context.shutdown()


def test_a_guard_condition_destroyed_by_the_executors_shutdown_is_a_clean_stop():
    """ros2/rclpy#968: shutdown() from another thread destroys the executor's guard
    condition while a task of the spin may still trigger it."""
    from rclpy.exceptions import InvalidHandle
    from rclpy.node import Node

    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node('spin_guard', context=context)
    guard = node.create_guard_condition(lambda: None)
    executor = SingleThreadedExecutor(context=context)

    def spin(shut_down_first: bool):
        if shut_down_first:
            executor.shutdown()
        guard.destroy()
        guard.trigger()  # raises InvalidHandle, as the spin's task does

    try:
        executor.spin = lambda: spin(shut_down_first=False)
        with pytest.raises(InvalidHandle):  # not shut down: a real error, raised
            spin_until_shutdown(executor)
        guard = node.create_guard_condition(lambda: None)
        executor.spin = lambda: spin(shut_down_first=True)
        spin_until_shutdown(executor, stopped=lambda: True)  # returns: nothing escapes
    finally:
        node.destroy_node()
        context.shutdown()
