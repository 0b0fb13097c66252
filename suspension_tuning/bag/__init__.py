"""Recording layer: rosbag2-style bags (metadata.yaml + one MCAP file), plain Python.

* :mod:`.definitions`: complete ``ros2msg`` definitions of msg, service-event and
  action types, in the layout rosbag2 writes;
* :mod:`.writer`: :class:`~.writer.BagWriter` (raw CDR, chunked, zstd, statistics,
  ``offered_qos_profiles``, the ``rosbag2`` metadata record, metadata.yaml);
* :mod:`.reader`: :func:`~.reader.read_messages` (tolerates truncated files),
  :func:`~.reader.decode`, :func:`~.reader.reindex`;
* :mod:`.recorder`: a recording session (one bag per optimisation run), used by the
  ``recorder`` node;
* :mod:`.foxglove`: decode bags with Foxglove's own npm libraries (node), as
  Foxglove opens them.
"""
