"""The environment of an isolated ROS test: DDS on loopback, a domain of its own.

No rclpy here: the pytest plugin applies this when the session starts, before any
test imports rclpy, and child processes a test starts (``ros2 run``-style nodes)
inherit it.
"""

from __future__ import annotations

import os
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

#: Fast DDS then sends discovery and data to 127.0.0.1 only (no multicast on the
#: machine's network interfaces).
LOOPBACK = 'LOCALHOST'
#: Variables that would widen discovery beyond loopback; removed while a test runs.
WIDENING = ('ROS_STATIC_PEERS', 'ROS_LOCALHOST_ONLY')
#: Domain ids handed out, within the portable 0..101 range (0 and the low ids are
#: where hand-started graphs usually live).
FIRST_DOMAIN_ID, N_DOMAIN_IDS = 10, 90


def default_domain_id() -> int:
    """The ROS_DOMAIN_ID of this process's tests: 10..99, from the process id.

    Parallel test sessions (or pytest-xdist workers) are separate processes and
    mostly get different domains, so their graphs do not see each other.
    """
    return FIRST_DOMAIN_ID + os.getpid() % N_DOMAIN_IDS


def loopback_values(domain_id: int) -> dict[str, str]:
    """The variables :func:`loopback_environment` sets."""
    if not 0 <= domain_id <= 232:  # rmw_fastrtps_cpp's limit for the port formula
        raise ValueError(f'ROS_DOMAIN_ID must be in 0..232, got {domain_id}')
    return {'ROS_AUTOMATIC_DISCOVERY_RANGE': LOOPBACK, 'ROS_DOMAIN_ID': str(domain_id)}


def _warn_if_overridden() -> None:
    previous = os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')
    if previous not in (None, LOOPBACK):
        print(f'suspension_tuning.testing: ROS_AUTOMATIC_DISCOVERY_RANGE={previous!r} '
              f'overridden with {LOOPBACK!r}: tests never use the real network',
              file=sys.stderr)


def apply_loopback_environment(domain_id: int) -> None:
    """Set the loopback environment for the rest of the process (pytest sessions).

    Also gives rclpy a log folder of its own (``ROS_LOG_DIR``, unless set) and, when
    the package's ament index is installed into this Python environment, puts the
    environment's prefix on ``AMENT_PREFIX_PATH`` as a sourced workspace would (the
    recorder finds message definitions and ``ros2 run``-style lookups find the
    executables there).
    """
    _warn_if_overridden()
    for name in WIDENING:
        os.environ.pop(name, None)
    os.environ.update(loopback_values(domain_id))
    os.environ.setdefault('ROS_LOG_DIR', tempfile.mkdtemp(prefix='suspension_tuning_roslog_'))
    prefixes = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    index = Path(sys.prefix, 'share', 'ament_index', 'resource_index', 'packages',
                 'suspension_tuning')
    if index.exists() and sys.prefix not in prefixes:
        os.environ['AMENT_PREFIX_PATH'] = os.pathsep.join([sys.prefix, *prefixes])


@contextmanager
def loopback_environment(domain_id: int) -> Iterator[None]:
    """Loopback discovery and ``ROS_DOMAIN_ID=domain_id`` while the block runs.

    The previous values come back afterwards, also when the block raises.
    """
    _warn_if_overridden()
    names = (*loopback_values(domain_id), *WIDENING)
    saved = {name: os.environ.get(name) for name in names}
    for name in WIDENING:
        os.environ.pop(name, None)
    os.environ.update(loopback_values(domain_id))
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def assert_loopback(domain_id: int) -> None:
    """Raise unless discovery is on loopback and the domain is ``domain_id``.

    Raises
    ------
    RuntimeError
        If something changed the environment: DDS must not start off loopback.
    """
    wanted = loopback_values(domain_id)
    found = {name: os.environ.get(name) for name in wanted}
    widening = [name for name in WIDENING if os.environ.get(name)]
    if found != wanted or widening:
        raise RuntimeError(f'refusing to start DDS: environment {found} (wanted {wanted})'
                           + (f', {", ".join(widening)} set' if widening else ''))
