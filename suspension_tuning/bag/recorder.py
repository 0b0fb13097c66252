"""Recording session (plain Python): which bag a message goes to, one bag per run.

The ``recorder`` node (:mod:`suspension_tuning.nodes.recorder`) feeds every received
message (raw CDR, receive and send times) to :meth:`RecordingSession.write`.  With
``per_run`` the session opens a new bag ``<YYYYmmdd-HHMMSS>_<scenario>`` when a message
arrives on ``/optimisation/run_config`` (std_msgs/String, the run's configuration
YAML; it marks the start of a run) and closes it after ``/optimisation/result`` (the
end of the run).  Messages between runs are held for ``pre_run_s`` (the action's
goal-accepted status can overtake the run_config on the way to the recorder) and
written at the start of the next run's bag; older ones are counted and dropped.  Without
``per_run`` everything goes to one bag for the whole session.  The run configuration
is also stored as the MCAP metadata record ``run_config``.
"""

from __future__ import annotations

import os
import re
import struct
import threading
import time
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from suspension_tuning.bag.writer import (
    DEFAULT_CHUNK_INTERVAL_S,
    DEFAULT_CHUNK_SIZE,
    BagWriter,
)

#: Topic whose message marks the start of a run (graph contract, brief/graph_api.md).
RUN_CONFIG_TOPIC = '/optimisation/run_config'
#: Topic whose message marks the end of a run.
RESULT_TOPIC = '/optimisation/result'


def decode_cdr_string(data: bytes) -> str:
    """The ``data`` field of a serialized std_msgs/String (CDR, either endianness).

    Raises
    ------
    ValueError
        If the bytes are not a CDR-encoded string message.
    """
    if len(data) < 8 or data[0] != 0 or data[1] not in (0, 1):
        raise ValueError('not a CDR message (bad encapsulation header)')
    (length,) = struct.unpack_from('<I' if data[1] else '>I', data, 4)
    if length == 0 or 8 + length > len(data):
        raise ValueError(f'CDR string length {length} does not fit in {len(data)} bytes')
    return data[8 : 8 + length - 1].decode('utf-8')


def run_bag_name(scenario: str, when_ns: int | None = None) -> str:
    """``<YYYYmmdd-HHMMSS>_<scenario>`` (UTC), scenario reduced to [A-Za-z0-9_-]."""
    seconds = (time.time_ns() if when_ns is None else when_ns) / 1e9
    stamp = time.strftime('%Y%m%d-%H%M%S', time.gmtime(seconds))
    safe = re.sub(r'[^A-Za-z0-9_-]+', '-', scenario).strip('-') or 'run'
    return f'{stamp}_{safe}'


def run_config_metadata(text: str) -> dict[str, str]:
    """MCAP metadata record ``run_config``: the YAML text and its top-level scalars."""
    record = {'yaml': text}
    try:
        loaded = yaml.safe_load(text)
    except yaml.YAMLError:
        loaded = None
    if isinstance(loaded, Mapping):
        for key, value in loaded.items():
            if isinstance(value, str | int | float | bool) and str(key) != 'yaml':
                record[str(key)] = str(value)
    return record


@dataclass
class TopicSpec:
    """What the session knows about a topic before any bag holds it."""

    name: str
    type: str
    offered_qos_profiles: list[dict[str, Any]] = field(default_factory=list)


class RecordingSession:
    """Route messages into bags under ``output_dir`` (thread-safe).

    Parameters
    ----------
    output_dir : str or Path
        Folder of the bags (created).
    bag_name : str
        Name of the session bag (``per_run`` False); '' = ``<YYYYmmdd-HHMMSS>_session``.
    per_run : bool
        One bag per optimisation run (see module docstring).
    chunk_size : int
        Chunk size of the bags, bytes.
    max_chunk_interval_s : float
        Longest time a chunk stays open, s.
    pre_run_s : float
        With ``per_run``: messages received up to this long (log time, s) before a
        run_config go into that run's bag.
    post_run_s : float
        With ``per_run``: the run's bag stays open until no message has arrived for
        this long (log time, s) after its result, for messages of the run still queued
        on other topics (the executor serves topics in no particular order; the
        reported design's telemetry is published just before the result, and on a
        busy machine its burst takes longer than any fixed grace to drain).  Only
        messages published before the result (their publish time, within
        ``post_run_s``) restart the grace; later ones are recorded while the bag is
        open but do not keep it open.
    post_run_max_s : float
        With ``per_run``: the bag closes at the latest this long after the result,
        whatever still arrives.
    """

    def __init__(
        self,
        output_dir: str | os.PathLike[str],
        bag_name: str = '',
        per_run: bool = True,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        max_chunk_interval_s: float = DEFAULT_CHUNK_INTERVAL_S,
        pre_run_s: float = 1.0,
        post_run_s: float = 1.0,
        post_run_max_s: float = 60.0,
    ) -> None:
        if pre_run_s < 0 or post_run_s < 0:
            raise ValueError(f'pre_run_s and post_run_s must not be negative, got '
                             f'{pre_run_s}, {post_run_s}')
        self.output_dir = Path(output_dir)
        self.bag_name = bag_name
        self.per_run = per_run
        self.chunk_size = chunk_size
        self.max_chunk_interval_s = max_chunk_interval_s
        self.topics: dict[str, TopicSpec] = {}
        self.bag: BagWriter | None = None
        self.closed_bags: list[Path] = []
        self.dropped = 0
        self.pre_run_ns = int(pre_run_s * 1e9)
        self.post_run_ns = int(post_run_s * 1e9)
        self.post_run_max_ns = int(max(post_run_max_s, post_run_s) * 1e9)
        self._close_at_ns: int | None = None
        self._close_by_ns: int | None = None
        self._result_sent_ns: int | None = None  # the finished run's result, publish time
        self._held: deque[tuple[str, bytes, int, int | None]] = deque()
        self._lock = threading.Lock()

    def add_topic(
        self, topic: str, type_name: str, offered_qos_profiles: Sequence[Mapping[str, Any]] = ()
    ) -> None:
        """Declare a topic; it enters a bag with its first message."""
        with self._lock:
            self.topics[topic] = TopicSpec(
                topic, type_name, [dict(p) for p in offered_qos_profiles]
            )

    def _unique(self, name: str) -> Path:
        path = self.output_dir / name
        k = 1
        while path.exists():
            path = self.output_dir / f'{name}_{k}'
            k += 1
        return path

    def _open(self, name: str) -> BagWriter:
        self.output_dir.mkdir(parents=True, exist_ok=True)
        self.bag = BagWriter(
            self._unique(name),
            chunk_size=self.chunk_size,
            max_chunk_interval_s=self.max_chunk_interval_s,
        )
        return self.bag

    def _close_bag(self) -> Path | None:
        self._close_at_ns = self._close_by_ns = self._result_sent_ns = None
        if self.bag is None:
            return None
        path = self.bag.close()
        self.closed_bags.append(path)
        self.bag = None
        return path

    def write(
        self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None,
        now_ns: int | None = None,
    ) -> Path | None:
        """Record one message; returns the path of a bag that this message closed, if any.

        ``now_ns`` is when the message is processed (the clock of :meth:`flush`; default
        ``log_time_ns``): a burst received before a run's result but processed after it
        keeps the run's bag open ``post_run_s`` past its last message.

        Raises
        ------
        ValueError
            If the topic was not declared with :meth:`add_topic`.
        """
        with self._lock:
            if topic not in self.topics:
                raise ValueError(f'topic {topic} was not declared with add_topic()')
            spec = self.topics[topic]
            closed = None
            if self._close_at_ns is not None and log_time_ns >= self._close_at_ns:
                closed = self._close_bag()
            if self.per_run and topic == RUN_CONFIG_TOPIC:
                text = decode_cdr_string(data)
                try:
                    loaded = yaml.safe_load(text) if text.strip() else {}
                except yaml.YAMLError:
                    loaded = {}
                scenario = (
                    str(loaded.get('scenario', 'run')) if isinstance(loaded, dict) else 'run'
                )
                self._close_bag()  # a run that never sent its result ends here
                bag = self._open(run_bag_name(scenario, log_time_ns))
                bag.add_metadata('run_config', run_config_metadata(text))
                bag.custom_data['scenario'] = scenario
                self._release_held(log_time_ns)
            elif self.bag is None:
                if self.per_run:
                    self._held.append((topic, bytes(data), log_time_ns, publish_time_ns))
                    self._prune_held(log_time_ns)
                    return closed
                self._open(self.bag_name or run_bag_name('session', log_time_ns))
            bag = self.bag
            if not self.per_run and topic == RUN_CONFIG_TOPIC:
                bag.add_metadata('run_config', run_config_metadata(decode_cdr_string(data)))
            if topic not in bag.topics:
                bag.add_topic(topic, spec.type, spec.offered_qos_profiles)
            bag.write(topic, data, log_time_ns, publish_time_ns)
            if self.per_run and topic == RESULT_TOPIC:
                if self.post_run_ns == 0:
                    return self._close_bag()
                now_ns = log_time_ns if now_ns is None else max(now_ns, log_time_ns)
                self._close_at_ns = now_ns + self.post_run_ns
                self._close_by_ns = now_ns + self.post_run_max_ns
                self._result_sent_ns = log_time_ns if publish_time_ns is None else publish_time_ns
            elif (self._close_at_ns is not None and self._close_by_ns is not None
                  and self._of_the_run(publish_time_ns)):
                # a message of the finished run: wait post_run_s after the last one
                now_ns = log_time_ns if now_ns is None else now_ns
                self._close_at_ns = min(self._close_by_ns,
                                        max(self._close_at_ns, now_ns + self.post_run_ns))
            return closed

    def _of_the_run(self, publish_time_ns: int | None) -> bool:
        """A message published before the finished run's result (within ``post_run_s``
        for clocks of other hosts), or of unknown publish time.

        Only those keep the bag open: the run's telemetry burst still queued, not what
        the graph publishes after the run (the goal's status when its result expires,
        log lines), which would otherwise hold the bag open up to ``post_run_max_s``.
        """  # noqa: D205
        return (publish_time_ns is None or self._result_sent_ns is None
                or publish_time_ns <= self._result_sent_ns + self.post_run_ns)

    def _prune_held(self, now_ns: int) -> None:
        while self._held and self._held[0][2] < now_ns - self.pre_run_ns:
            self._held.popleft()
            self.dropped += 1

    def _release_held(self, now_ns: int) -> None:
        """Write the held messages of the last ``pre_run_s`` into the new bag."""
        self._prune_held(now_ns)
        while self._held:
            topic, data, log_ns, publish_ns = self._held.popleft()
            spec = self.topics[topic]
            if topic not in self.bag.topics:
                self.bag.add_topic(topic, spec.type, spec.offered_qos_profiles)
            self.bag.write(topic, data, log_ns, publish_ns)

    def flush(self, now_ns: int | None = None) -> Path | None:
        """Push the open chunk to disk; close a finished run's bag once its grace is over.

        Returns the path of the bag closed, if any.
        """
        now_ns = time.time_ns() if now_ns is None else now_ns
        with self._lock:
            if self._close_at_ns is not None and now_ns >= self._close_at_ns:
                return self._close_bag()
            if self.bag is not None:
                self.bag.flush()
            return None

    def close(self) -> Path | None:
        """Finalise the open bag (summary, metadata.yaml); returns its path."""
        with self._lock:
            return self._close_bag()
