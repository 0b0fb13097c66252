"""pytest plugin of the testing kit (entry point ``pytest11``: ``suspension_tuning``).

Loaded by pytest whenever the package is installed; ``-p no:suspension_tuning``
turns it off.  At the start of the session it reserves the session's ROS domain on
the machine (:func:`reserved_domain`, held until the session ends) and keeps DDS
discovery on loopback (:func:`apply_loopback_environment`), before any test starts
rclpy; the fixtures are listed in :mod:`suspension_tuning.testing`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import pytest
from rclpy.context import Context

from suspension_tuning.testing import (
    DomainInUseError,
    SpinningExecutor,
    TuningGraph,
    apply_loopback_environment,
    isolated_context,
    raise_callback_errors,
    reserved_domain,
    spinning_executor,
)

_DOMAIN_ID = pytest.StashKey[int]()
_RESERVATION = pytest.StashKey[AbstractContextManager[int]]()


def pytest_addoption(parser: pytest.Parser) -> None:
    """``--ros-domain-id``: the session's ROS domain (default: a free one of 10..99)."""
    group = parser.getgroup('suspension_tuning', 'suspension_tuning testing kit')
    group.addoption('--ros-domain-id', type=int, default=None, dest='ros_domain_id',
                    help='ROS_DOMAIN_ID of the ROS tests, reserved for the session; '
                         'fails if another session holds it (default: the first free '
                         'one of 10..99 from 10 + pid %% 90 on)')


def pytest_configure(config: pytest.Config) -> None:
    """The session's domain, reserved, and loopback discovery, before rclpy starts."""
    wanted = config.getoption('ros_domain_id')
    reservation = reserved_domain(wanted)
    try:
        domain = reservation.__enter__()
    except DomainInUseError as error:
        raise pytest.UsageError(
            f'--ros-domain-id {wanted}: {error}.  Choose another with --ros-domain-id N, '
            'or leave the option out: the session then takes a free domain.') from None
    except ValueError as error:
        raise pytest.UsageError(f'--ros-domain-id {wanted}: {error}') from None
    config.stash[_RESERVATION] = reservation
    apply_loopback_environment(domain)
    config.stash[_DOMAIN_ID] = domain
    config.addinivalue_line(
        'markers', 'ros: uses rclpy and DDS (loopback only, the session\'s own domain id)')


def pytest_unconfigure(config: pytest.Config) -> None:
    """Release the session's domain."""
    reservation = config.stash.get(_RESERVATION, None)
    if reservation is not None:
        del config.stash[_RESERVATION]
        reservation.__exit__(None, None, None)


@pytest.fixture(scope='session')
def ros_domain_id(pytestconfig: pytest.Config) -> int:
    """The ROS_DOMAIN_ID of this test session."""
    return pytestconfig.stash[_DOMAIN_ID]


@pytest.fixture
def ros_context(ros_domain_id: int) -> Iterator[Context]:
    """An isolated, initialised rclpy Context on loopback, shut down after the test."""
    with isolated_context(ros_domain_id) as context:
        yield context


@pytest.fixture
def ros_executor(ros_context: Context) -> Iterator[SpinningExecutor]:
    """A MultiThreadedExecutor spinning in a background thread (``.add(*nodes)``).

    Its nodes are destroyed after the test; a callback that raised while it spun
    fails the test (:class:`~suspension_tuning.testing.CallbackError`).
    """
    with spinning_executor(ros_context) as spinning:
        yield spinning


@pytest.fixture
def start_tuning_graph(ros_context: Context,
                       tmp_path: Path) -> Iterator[Callable[..., TuningGraph]]:
    """``start_tuning_graph(record=False, **options)``: the graph on the test's context.

    ``record=True`` adds the recorder, writing into ``tmp_path / 'bags'``; the
    gradient evaluator caches its calibrations in ``tmp_path / 'calibration'`` (each
    test calibrates afresh, whatever ran before); the other options are those of
    :class:`~suspension_tuning.testing.TuningGraph` (``workers``, ``replace``,
    ``parameters``, ``num_threads``).  Every graph started is shut down after the
    test, and a callback that raised while it spun fails the test.
    """
    graphs: list[TuningGraph] = []

    def start(record: bool = False, **options: Any) -> TuningGraph:
        if record:
            options.setdefault('record_dir', tmp_path / 'bags')
        options.setdefault('calibration_dir', tmp_path / 'calibration')
        graphs.append(TuningGraph(ros_context, **options))
        return graphs[-1]

    try:
        yield start
    finally:
        for graph in reversed(graphs):
            graph.shutdown()
    raise_callback_errors([error for graph in graphs for error in graph.errors])
