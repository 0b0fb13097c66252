"""The environment of an isolated ROS test: DDS on loopback, a domain of its own.

No rclpy here: the pytest plugin applies this when the session starts, before any
test imports rclpy, and child processes a test starts (``ros2 run``-style nodes)
inherit it.

A domain handed out is reserved on the machine for as long as it is used, as
launch_testing reserves its domains (``domain_coordinator``: a TCP socket bound to
port 32768 + id, never listening, so nothing goes on the network): two processes
that reserve never get the same domain.
"""

from __future__ import annotations

import os
import sys
import tempfile
import threading
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path

import domain_coordinator
from domain_coordinator.impl import PORT_BASE

#: Fast DDS then sends discovery and data to 127.0.0.1 only (no multicast on the
#: machine's network interfaces).
LOOPBACK = 'LOCALHOST'
#: Variables that would widen discovery beyond loopback; removed while a test runs.
WIDENING = ('ROS_STATIC_PEERS', 'ROS_LOCALHOST_ONLY')
#: Domain ids handed out, within the portable 0..101 range (0 and the low ids are
#: where hand-started graphs usually live).
FIRST_DOMAIN_ID, N_DOMAIN_IDS = 10, 90


def default_domain_id() -> int:
    """Where this process's search for a free domain starts: 10..99, from the process id.

    :func:`reserved_domain` takes this domain, or the next one (10..99, wrapping
    round) that no other process has reserved.
    """
    return FIRST_DOMAIN_ID + os.getpid() % N_DOMAIN_IDS


def reservation_port(domain_id: int) -> int:
    """The TCP port whose binding reserves ``domain_id`` on this machine."""
    return PORT_BASE + domain_id


class DomainInUseError(RuntimeError):
    """The domain asked for is reserved by another process (the message says which)."""


class _ExhaustedError(Exception):
    """Raised by :class:`_Candidates` when every candidate was tried."""


class _Candidates:
    """A ``domain_coordinator`` selector: each of ``ids`` once, then :class:`_ExhaustedError`."""

    def __init__(self, ids: list[int]) -> None:
        self._ids = iter(ids)

    def __call__(self) -> int:
        try:
            return next(self._ids)
        except StopIteration:
            raise _ExhaustedError from None


def _search_order(first: int) -> list[int]:
    """10..99 from ``first`` on, wrapping round."""
    offset = (first - FIRST_DOMAIN_ID) % N_DOMAIN_IDS
    return [FIRST_DOMAIN_ID + (offset + k) % N_DOMAIN_IDS for k in range(N_DOMAIN_IDS)]


def _reserve(ids: list[int]) -> tuple[int, AbstractContextManager[int]] | None:
    """The first of ``ids`` this process could reserve, and its reservation, or None."""
    reservation = domain_coordinator.domain_id(_Candidates(ids))
    try:
        domain = reservation.__enter__()
    except _ExhaustedError:
        return None
    return domain, reservation


def free_domain_id(after: int) -> int | None:
    """A domain of 10..99 that no process reserves right now (after ``after``), or None."""
    found = _reserve(_search_order(after + 1))
    if found is None:
        return None
    domain, reservation = found
    reservation.__exit__(None, None, None)
    return domain


#: This process's reservations: domain -> [reservation, number of users], oldest first.
_held: dict[int, list] = {}
_held_lock = threading.Lock()


def _acquire(domain_id: int | None) -> int:
    if domain_id is not None:
        loopback_values(domain_id)  # ValueError outside 0..232
    with _held_lock:
        if domain_id is None and _held:
            domain_id = next(iter(_held))  # the process's domain
        if domain_id in _held:
            _held[domain_id][1] += 1
            return domain_id
        ids = _search_order(default_domain_id()) if domain_id is None else [domain_id]
        found = _reserve(ids)
        if found is None and domain_id is None:
            raise DomainInUseError(
                f'no free ROS domain: every one of {FIRST_DOMAIN_ID}..'
                f'{FIRST_DOMAIN_ID + N_DOMAIN_IDS - 1} is reserved by another process on '
                f'this machine (TCP ports {reservation_port(FIRST_DOMAIN_ID)}..'
                f'{reservation_port(FIRST_DOMAIN_ID + N_DOMAIN_IDS - 1)} bound)')
        if found is None:
            free = free_domain_id(domain_id)
            raise DomainInUseError(
                f'ROS domain {domain_id} is reserved by another process on this machine '
                f'(TCP port {reservation_port(domain_id)} is bound: most likely another '
                'test session on that domain, which this one would disturb)'
                + (f'; domain {free} is free now' if free is not None else ''))
        domain, reservation = found
        _held[domain] = [reservation, 1]
        return domain


def _release(domain_id: int) -> None:
    with _held_lock:
        entry = _held[domain_id]
        entry[1] -= 1
        if entry[1] == 0:
            del _held[domain_id]
            entry[0].__exit__(None, None, None)  # closes the socket: the port is free


@contextmanager
def reserved_domain(domain_id: int | None = None) -> Iterator[int]:
    """A ROS domain reserved on this machine while the block runs.

    The reservation is launch_testing's (``domain_coordinator``): this process binds
    TCP port 32768 + id (:func:`reservation_port`) and never listens on it, so nothing
    goes on the network, and no other process that reserves gets the same domain.

    Parameters
    ----------
    domain_id : int, optional
        The domain wanted.  By default the domain this process already holds (a
        pytest session's, say), else the first free one of 10..99 from
        :func:`default_domain_id` on.  Blocks of one process that ask for the same
        domain share its reservation; it ends with the last of them.

    Yields
    ------
    int
        The reserved domain id.

    Raises
    ------
    DomainInUseError
        If ``domain_id`` is reserved by another process (the message names it and a
        free one), or no domain of 10..99 is free.
    """
    domain = _acquire(domain_id)
    try:
        yield domain
    finally:
        # Released here, never through domain_coordinator's own exit with the block's
        # exception: it swallows an OSError (a TimeoutError, say) of the block.
        _release(domain)


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
