"""ROS 2 node ``recorder``: every topic of the graph into rosbag2-style MCAP bags.

Discovers topics periodically (``get_topic_names_and_types`` lists the hidden
``<service>/_service_event`` and ``<action>/_action/{feedback,status}`` topics too),
subscribes to each with ``raw=True`` (the CDR bytes are stored as received, never
re-encoded) and a QoS the publishers can serve (reliable only if every publisher
offers reliable, transient local only if every publisher offers it), and hands each
message, with its receive time (log time) and send time (publish time) from the
middleware's message info, to :class:`suspension_tuning.bag.recorder.RecordingSession`.
The publishers' offered QoS is stored as each channel's ``offered_qos_profiles``.

Parameters (config/recorder.yaml): ``output_dir``, ``bag_name``, ``per_run``,
``topics``, ``exclude_regex``, ``discovery_period_s``, ``chunk_size_bytes``,
``max_chunk_interval_s``, ``pre_run_s``, ``post_run_s``.

Ctrl-C (SIGINT) or SIGTERM finalises the open bag (summary, statistics,
metadata.yaml).  A recorder killed with SIGKILL leaves a bag that reads up to its
last chunk (``suspension_tuning.bag.reader.read_messages``; repair with ``reindex``).

Run: ``ros2 run suspension_tuning recorder --ros-args --params-file config/recorder.yaml``.
"""

from __future__ import annotations

import re
import threading
import time

from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)

from suspension_tuning.bag.definitions import (
    DefinitionNotFoundError,
    definition_text,
    message_class,
)
from suspension_tuning.bag.recorder import RecordingSession
from suspension_tuning.bag.writer import qos_profile_dict
from suspension_tuning.config_check import check_config
from suspension_tuning.nodes._parameters import declare_numbers, read_only
from suspension_tuning.nodes._spin import run_node

#: Depth of the recorder's subscriptions: deep enough that a burst of telemetry (a 20 s
#: run at 200 Hz is 4000 samples per topic) waits instead of being overwritten while the
#: recorder drains it (Fast DDS also caps a reader at 5000 samples by default).
SUBSCRIPTION_DEPTH = 10000


def _name(policy: object) -> str:
    """rclpy policy enum -> rosbag2 name (RELIABLE -> 'reliable', ...)."""
    name = getattr(policy, 'name', '')
    return name.lower() if name else 'unknown'


def _duration(value) -> dict[str, int]:
    """rclpy Duration -> rosbag2 {sec, nsec} (infinite as rosbag2 writes it)."""
    ns = value.nanoseconds
    if ns >= (1 << 63) - 1 or ns == 0x7FFFFFFFFFFFFFFF:
        return {'sec': 2147483647, 'nsec': 4294967295}
    return {'sec': ns // 1_000_000_000, 'nsec': ns % 1_000_000_000}


def offered_qos(profile: QoSProfile) -> dict:
    """An endpoint's QoS profile in rosbag2 version-9 form."""
    return qos_profile_dict(
        reliability=_name(profile.reliability),
        durability=_name(profile.durability),
        history=_name(profile.history),
        depth=profile.depth,
        deadline=_duration(profile.deadline),
        lifespan=_duration(profile.lifespan),
        liveliness=_name(profile.liveliness),
        liveliness_lease_duration=_duration(profile.liveliness_lease_duration),
        avoid_ros_namespace_conventions=profile.avoid_ros_namespace_conventions,
    )


def subscription_qos(offered: list[QoSProfile]) -> QoSProfile:
    """A subscription QoS every offering publisher is compatible with.

    Reliable only if all publishers are reliable (a reliable reader gets nothing from
    a best-effort writer), transient local only if all are (then the latched
    run_config/result arrive even if published before the recorder subscribed).
    """
    reliable = all(p.reliability == ReliabilityPolicy.RELIABLE for p in offered)
    latched = all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in offered)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=SUBSCRIPTION_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


class RecorderNode(Node):
    """Subscribe to every (selected) topic raw and record it."""

    def __init__(self, **kwargs) -> None:
        check_config(builtin_model=False)  # ConfigError: one line, before the node exists
        super().__init__('recorder', **kwargs)
        string_array = ParameterDescriptor(type=ParameterType.PARAMETER_STRING_ARRAY)
        self.declare_parameter('output_dir', 'bags')
        self.declare_parameter('bag_name', '')
        self.declare_parameter('per_run', True)
        self.declare_parameter('topics', [''], string_array)
        self.declare_parameter('exclude_regex', '')
        declare_numbers(self, {'discovery_period_s': 0.5, 'chunk_size_bytes': 512 * 1024,
                               'max_chunk_interval_s': 1.0, 'pre_run_s': 1.0,
                               'post_run_s': 3.0})
        # Every one read once, here and just below.
        read_only(self, ['output_dir', 'bag_name', 'per_run', 'topics', 'exclude_regex',
                         'discovery_period_s', 'chunk_size_bytes', 'max_chunk_interval_s',
                         'pre_run_s', 'post_run_s'])
        param = self.get_parameter
        self.only = {t for t in param('topics').value if t}
        pattern = param('exclude_regex').value
        self.exclude = re.compile(pattern) if pattern else None
        self.session = RecordingSession(
            param('output_dir').value,
            bag_name=param('bag_name').value,
            per_run=param('per_run').value,
            chunk_size=int(param('chunk_size_bytes').value),
            max_chunk_interval_s=float(param('max_chunk_interval_s').value),
            pre_run_s=float(param('pre_run_s').value),
            post_run_s=float(param('post_run_s').value),
        )
        self.subscribed: dict[str, str] = {}
        self.skipped: dict[str, str] = {}
        self.received = 0
        self._lock = threading.Lock()
        self._discovery_group = MutuallyExclusiveCallbackGroup()
        self._message_group = MutuallyExclusiveCallbackGroup()
        self.discover()
        # A quiet topic must not leave its messages in an open chunk: push the open
        # chunk to disk at least this often (what a SIGKILL can lose).
        self.create_timer(
            min(float(param('max_chunk_interval_s').value), 0.25),
            self._flush,
            callback_group=self._message_group,
        )
        self.create_timer(
            float(param('discovery_period_s').value),
            self.discover,
            callback_group=self._discovery_group,
        )
        self.get_logger().info(
            f'recording into {self.session.output_dir} '
            f'({"one bag per run" if self.session.per_run else "one bag"})'
        )

    def wanted(self, topic: str) -> bool:
        """Whether a topic passes the ``topics`` and ``exclude_regex`` filters."""
        if self.only and topic not in self.only:
            return False
        return not (self.exclude is not None and self.exclude.search(topic))

    def discover(self) -> None:
        """Subscribe to topics that appeared since the last look."""
        with self._lock:
            for topic, types in self.get_topic_names_and_types():
                if topic in self.subscribed or topic in self.skipped or not self.wanted(topic):
                    continue
                if len(types) != 1:
                    self.skipped[topic] = f'several types {types}'
                    self.get_logger().warning(f'not recording {topic}: several types {types}')
                    continue
                type_name = types[0]
                try:
                    definition_text(type_name)
                except (DefinitionNotFoundError, ValueError, ImportError) as exc:
                    self.skipped[topic] = str(exc)
                    self.get_logger().warning(f'not recording {topic} ({type_name}): {exc}')
                    continue
                publishers = self.get_publishers_info_by_topic(topic)
                if not publishers:
                    continue  # only subscribers so far: look again later
                try:
                    msg_type = message_class(type_name)
                except (DefinitionNotFoundError, ImportError, ValueError) as exc:
                    self.skipped[topic] = str(exc)
                    self.get_logger().warning(f'not recording {topic} ({type_name}): {exc}')
                    continue
                profiles = [p.qos_profile for p in publishers]
                try:
                    offers = [offered_qos(p) for p in profiles]
                except ValueError as exc:
                    self.get_logger().warning(f'{topic}: offered QoS not stored: {exc}')
                    offers = []
                self.session.add_topic(topic, type_name, offers)
                self.create_subscription(
                    msg_type,
                    topic,
                    lambda data, info, t=topic: self._on_message(t, data, info),
                    subscription_qos(profiles),
                    raw=True,
                    callback_group=self._message_group,
                )
                self.subscribed[topic] = type_name
                self.get_logger().info(f'recording {topic} ({type_name})')

    def _on_message(self, topic: str, data: bytes, info: dict) -> None:
        received = int(info.get('received_timestamp') or 0) or time.time_ns()
        sent = int(info.get('source_timestamp') or 0) or received
        try:
            closed = self.session.write(topic, data, received, sent, now_ns=time.time_ns())
        except Exception as exc:  # noqa: BLE001 - never let one message stop the recorder
            self.get_logger().error(f'message on {topic} not recorded: {exc!r}')
            return
        self.received += 1
        if closed is not None:  # once per run, on the message thread: the fast path
            self.get_logger().info(f'bag closed: {closed}')

    def _flush(self) -> None:
        closed = self.session.flush()
        if closed is not None:
            self.get_logger().info(f'bag closed: {closed}')

    def close(self) -> None:
        """Finalise the open bag."""
        path = self.session.close()
        if path is not None:
            self.get_logger().info(f'bag closed: {path}')

    def destroy_node(self) -> None:
        """Finalise the open bag, then destroy the node."""
        self.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run suspension_tuning recorder``."""
    # Single-threaded: no callback blocks, and rclpy's MultiThreadedExecutor costs more
    # per message (benchmarks/bench_recorder.py, this 2-core machine: 3900-6100 against
    # 1900-2400 messages/s).
    run_node(RecorderNode, args, name='recorder')


if __name__ == '__main__':
    main()
