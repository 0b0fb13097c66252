"""Test harness: DDS kept on loopback, a domain of its own, rclpy on executors.

Every test session:

- forces ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (Fast DDS then sends discovery
  and data only to 127.0.0.1; multicast on the machine's network interface is
  forbidden here) and fails loudly if anything changes it before rclpy starts;
- picks its own ``ROS_DOMAIN_ID`` so parallel sessions do not see each other;
- gives tests an isolated rclpy ``Context`` and a ``MultiThreadedExecutor`` spinning
  in a background thread, shut down cleanly after each test.

Per-test timeouts come from pytest-timeout (``pytest.ini``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import threading
from collections.abc import Iterator

import pytest

LOOPBACK = 'LOCALHOST'
_previous = os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')
if _previous not in (None, LOOPBACK):
    print(f'conftest: ROS_AUTOMATIC_DISCOVERY_RANGE={_previous!r} overridden with '
          f'{LOOPBACK!r}: tests never use the real network', file=sys.stderr)
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = LOOPBACK
os.environ.pop('ROS_STATIC_PEERS', None)
os.environ.pop('ROS_LOCALHOST_ONLY', None)
# Domain ids 10..99 (within the portable 0..101 range); one per test session.
DOMAIN_ID = 10 + os.getpid() % 90
os.environ['ROS_DOMAIN_ID'] = str(DOMAIN_ID)
os.environ.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
os.environ.setdefault('ROS_LOG_DIR', tempfile.mkdtemp(prefix='suspension_tuning_roslog_'))
# The venv is an ament prefix (make setup registers the package there), as a sourced
# ROS workspace would be.
_prefixes = os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)
if sys.prefix not in _prefixes:
    os.environ['AMENT_PREFIX_PATH'] = os.pathsep.join([sys.prefix, *filter(None, _prefixes)])


def _clean_stale_shared_memory() -> None:
    """Remove Fast DDS shared-memory segments left by killed processes.

    SIGKILLed participants (the worker-failure test kills two) leave their segments and
    port locks in /dev/shm; with hundreds of them, replies were seen to arrive seconds
    late.  ``fastdds shm clean`` removes only segments no live process uses.
    """
    tool = os.path.join(sys.prefix, 'bin', 'fastdds')
    if os.path.exists(tool):
        subprocess.run([tool, 'shm', 'clean'], capture_output=True, timeout=60, check=False)


_clean_stale_shared_memory()


def assert_loopback_only() -> None:
    """Fail loudly unless DDS discovery is still confined to loopback."""
    value = os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE')
    if value != LOOPBACK or os.environ.get('ROS_STATIC_PEERS'):
        pytest.exit(f'ROS_AUTOMATIC_DISCOVERY_RANGE was changed to {value!r} (or '
                    'ROS_STATIC_PEERS set): refusing to start DDS off loopback',
                    returncode=3)


@pytest.fixture(scope='session')
def ros_domain_id() -> int:
    """The ROS_DOMAIN_ID of this test session."""
    return DOMAIN_ID


@pytest.fixture
def ros_context() -> Iterator[object]:
    """An isolated, initialised rclpy context, shut down after the test."""
    import rclpy
    from rclpy.context import Context

    assert_loopback_only()
    context = Context()
    rclpy.init(context=context, domain_id=DOMAIN_ID)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)
        context.destroy()


class SpinningExecutor:
    """A MultiThreadedExecutor spinning in a background thread."""

    def __init__(self, context: object, num_threads: int = 4) -> None:
        from rclpy.executors import MultiThreadedExecutor

        self.executor = MultiThreadedExecutor(num_threads=num_threads, context=context)
        self.nodes: list = []
        self.stopped = False
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        from suspension_tuning.nodes._spin import spin_until_shutdown

        spin_until_shutdown(self.executor, stopped=lambda: self.stopped)  # ends quietly

    def add(self, *nodes: object) -> None:
        """Add nodes; they are destroyed when the executor shuts down."""
        for node in nodes:
            self.executor.add_node(node)
            self.nodes.append(node)

    def shutdown(self) -> None:
        """Stop spinning, join the thread and destroy the nodes."""
        self.stopped = True
        self.executor.shutdown(timeout_sec=5.0)
        self._thread.join(timeout=10.0)
        for node in self.nodes:
            node.destroy_node()


@pytest.fixture
def executor(ros_context: object) -> Iterator[SpinningExecutor]:
    """A spinning MultiThreadedExecutor on the test's own context."""
    spinning = SpinningExecutor(ros_context)
    try:
        yield spinning
    finally:
        spinning.shutdown()


@pytest.fixture
def in_process_optimum():
    """``run(options, n_samples, scenario='ride')``: the 2-variable optimisation, in-process.

    Simplified-model gradients scaled by the in-process eq. 25 calibration from
    ``n_samples`` full-model runs, the full model through ``evaluation.evaluate`` as
    in the simulation node (handling: its steering and slip angles go to the
    simplified model, paper 6.1): the bits a run through the graph must reach.
    """
    def run(options: dict, n_samples: int, scenario: str = 'ride'):
        from suspension_tuning import evaluation
        from suspension_tuning.optim.simplified_gradient import SimplifiedGradient, calibrate
        from suspension_tuning.tuning import FullEvaluation, TuningRequest, optimise

        scaling = calibrate(scenario, 2, n_samples=n_samples,
                            run_full=lambda name, x: evaluation.evaluate(name, x).result)

        def full_model(points):
            evaluated = evaluation.evaluate(scenario, points)
            return FullEvaluation(evaluated.f, evaluated.g, evaluated.result)

        return optimise(TuningRequest(scenario, 2, None, 'simplified', options), full_model,
                        SimplifiedGradient(scenario, 2, scaling))
    return run


@pytest.fixture
def foxglove_check():
    """``check(bags, messages=False)``: decode bags with Foxglove's own npm libraries.

    Skips the test, saying why, where node or the packages ``make setup`` installs into
    tools/foxglove/node_modules are missing (see suspension_tuning/bag/foxglove.py).
    """
    from suspension_tuning.bag import foxglove

    reason = foxglove.unavailable_reason()
    if reason:
        pytest.skip(f'Foxglove decoding check not run: {reason}')
    return foxglove.check
