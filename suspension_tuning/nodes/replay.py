"""ROS 2 node ``replay``: republish a bag onto the graph's topics, like ``ros2 bag play``.

Reads a bag (folder or ``.mcap``; a truncated one too, up to its last complete
chunk), creates one publisher per topic with the QoS the original publishers offered
(``offered_qos_profiles``: reliability, durability, history depth; so latched topics
such as ``/optimisation/run_config`` latch again), and publishes the recorded CDR bytes
unchanged in log-time order, each at ``start + (log_time - first_log_time) / rate``
(absolute targets on the monotonic clock, so timing errors do not accumulate).

Parameters: ``bag`` (path; if empty the node waits until it is set, e.g. with
``ros2 param set /replay bag bags/x``), ``rate`` (time factor, 2 = twice as fast),
``topics`` (only these; [''] = all), ``loop``, ``publish_clock`` (rosgraph_msgs/Clock
on ``/clock`` with the recorded log time before each message, for ``use_sim_time``
listeners; not when the bag holds ``/clock`` itself), ``start_delay_s`` (time for
subscribers to match the new publishers before the first message).  The node exits
when playback is done (unless ``loop``), so ``ros2 run suspension_tuning replay
--ros-args -p bag:=bags/x`` finishes by itself.
"""

from __future__ import annotations

import sys
import threading
import time

import rclpy
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

from suspension_tuning.bag.definitions import DefinitionNotFoundError, message_class
from suspension_tuning.bag.reader import BagContents, read_messages
from suspension_tuning.nodes._parameters import declare_numbers
from suspension_tuning.nodes._spin import settle_signal, spin_until_shutdown

#: Depth used when the bag records no offered QoS (rosbag2's Rosbag2QoS default, keep
#: last 10, reliable, volatile: jazzy rosbag2_transport qos.hpp).
DEFAULT_DEPTH = 10


def recorded_qos(profiles: list[dict]) -> QoSProfile:
    """The publisher QoS for a topic from its recorded offered profiles.

    Several publishers: reliable only if all offered reliable, transient local only if
    all offered it (what every original subscriber could rely on).
    """
    if not profiles:
        return QoSProfile(
            depth=DEFAULT_DEPTH,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.VOLATILE,
        )
    reliable = all(p.get('reliability') == 'reliable' for p in profiles)
    latched = all(p.get('durability') == 'transient_local' for p in profiles)
    keep_all = all(p.get('history') == 'keep_all' for p in profiles)
    depth = max(int(p.get('depth') or 0) for p in profiles) or DEFAULT_DEPTH
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if keep_all else HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


class ReplayNode(Node):
    """Publish the messages of a bag at the recorded timing times ``1 / rate``."""

    def __init__(self, **kwargs) -> None:
        super().__init__('replay', **kwargs)
        string_array = ParameterDescriptor(type=ParameterType.PARAMETER_STRING_ARRAY)
        self.declare_parameter('bag', '')
        declare_numbers(self, {'rate': 1.0})
        self.declare_parameter('topics', [''], string_array)
        self.declare_parameter('loop', False)
        self.declare_parameter('publish_clock', False)
        declare_numbers(self, {'start_delay_s': 0.5})
        self.done = threading.Event()
        self.published = 0
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.add_post_set_parameters_callback(self._on_parameters)
        if self.get_parameter('bag').value:
            self.start()
        else:
            self.get_logger().info("no bag given: waiting for parameter 'bag'")

    def _on_parameters(self, parameters) -> None:
        if any(p.name == 'bag' and p.value for p in parameters) and self._thread is None:
            try:
                self.start()
            except ValueError as error:
                self.get_logger().error(f'cannot replay: {error}')

    def start(self) -> None:
        """Open the bag, create the publishers and start playback in a thread.

        Raises
        ------
        ValueError
            If ``rate`` is not positive or the bag cannot be read.
        """
        rate = float(self.get_parameter('rate').value)
        if not rate > 0:
            raise ValueError(f'rate must be positive, got {rate}')
        path = self.get_parameter('bag').value
        only = {t for t in self.get_parameter('topics').value if t}
        contents = read_messages(path, topics=only or None)
        if not contents.complete and contents.message_count == 0:
            raise ValueError(f'{path}: {contents.stop_reason}: nothing to replay')
        if not contents.complete:
            self.get_logger().warning(
                f'{path}: {contents.stop_reason}; replaying the {contents.message_count} '
                'messages of its complete chunks'
            )
        publishers = {}
        for channel in contents.channels.values():
            if only and channel.topic not in only or channel.topic in publishers:
                continue
            try:
                msg_type = message_class(channel.type)
            except (DefinitionNotFoundError, ValueError) as exc:
                self.get_logger().warning(f'not replaying {channel.topic}: {exc}')
                continue
            publishers[channel.topic] = self.create_publisher(
                msg_type, channel.topic, recorded_qos(channel.offered_qos_profiles)
            )
        clock = None
        if self.get_parameter('publish_clock').value and '/clock' not in publishers:
            clock = self.create_publisher(Clock, '/clock', 10)
        self._thread = threading.Thread(
            target=self._play, args=(contents, publishers, clock, rate), daemon=True
        )
        self._thread.start()

    def _play(self, contents: BagContents, publishers: dict, clock, rate: float) -> None:
        messages = [m for m in contents.messages if m.topic in publishers]
        self.get_logger().info(
            f'replaying {len(messages)} messages on {len(publishers)} topics, '
            f'{contents.duration_ns / 1e9:.3f} s recorded, rate {rate:g}'
        )
        if self._stop.wait(float(self.get_parameter('start_delay_s').value)):
            return
        try:
            while True:
                self._play_once(messages, publishers, clock, rate)
                if self._stop.is_set() or not self.get_parameter('loop').value:
                    break
        except Exception as exc:  # noqa: BLE001 - a shut-down context ends playback
            if not self._stop.is_set():
                self.get_logger().error(f'playback stopped: {exc!r}')
        self.get_logger().info(f'replay done: {self.published} messages published')
        self.done.set()

    def _play_once(self, messages, publishers: dict, clock, rate: float) -> None:
        if not messages:
            return
        first = messages[0].log_time_ns
        start = time.monotonic_ns()
        for message in messages:
            target = start + int((message.log_time_ns - first) / rate)
            while (wait := target - time.monotonic_ns()) > 0:
                if self._stop.wait(wait / 1e9):
                    return
            if clock is not None:
                stamp = Clock()
                stamp.clock.sec, stamp.clock.nanosec = divmod(message.log_time_ns, 1_000_000_000)
                clock.publish(stamp)
            publishers[message.topic].publish(message.data)
            self.published += 1

    def stop(self) -> None:
        """Stop playback and wait for the playback thread."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    def destroy_node(self) -> None:
        """Stop playback, then destroy the node."""
        self.stop()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run suspension_tuning replay``: returns when playback ends."""
    rclpy.init(args=args)
    try:
        node = ReplayNode()
    except ValueError as error:
        print(f'replay: {error}', file=sys.stderr)
        rclpy.try_shutdown()
        sys.exit(2)
    executor = MultiThreadedExecutor(num_threads=2)
    executor.add_node(node)
    try:
        spin_until_shutdown(executor, until=node.done.is_set)
        if node.done.is_set():
            # Let reliable subscribers fetch the last samples before the publishers go.
            time.sleep(0.2)
    except KeyboardInterrupt:  # Ctrl-C during that last wait
        pass
    finally:
        if not node.done.is_set():  # Ctrl-C or SIGTERM (_spin.settle_signal has why)
            settle_signal(executor.context)
        node.destroy_node()
        executor.shutdown(timeout_sec=1.0)
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
