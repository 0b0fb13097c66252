"""The project's own test harness, over the testing kit.

The ROS fixtures come from the package's pytest plugin
(``suspension_tuning.testing``, loaded through its ``pytest11`` entry point): it
keeps DDS discovery on loopback (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) with a
domain of the session's own, and gives each test an isolated rclpy context
(``ros_context``), a spinning executor (``ros_executor``, here also ``executor``)
and the graph (``start_tuning_graph``).  Per-test timeouts come from pytest-timeout
(``pytest.ini``).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest


def _clean_stale_shared_memory() -> None:
    """Remove Fast DDS shared-memory segments left by killed processes.

    SIGKILLed participants (the worker-failure test kills two) leave their segments and
    port locks in /dev/shm; with hundreds of them, replies were seen to arrive seconds
    late.  ``fastdds shm clean`` removes only segments no live process uses.
    """
    tool = os.path.join(sys.prefix, 'bin', 'fastdds')
    if os.path.exists(tool):
        subprocess.run([tool, 'shm', 'clean'], capture_output=True, timeout=60, check=False)


os.environ.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
# The node executables' start-up check for a node of their name on the domain waits up
# to 3.5 s for discovery (nodes/_unique.py); the tests start dozens of them on a domain
# of their own, so 0.5 s here.  The tests of the check itself set a longer window.
os.environ.setdefault('SUSPENSION_TUNING_DISCOVERY_WINDOW_S', '0.5')
_clean_stale_shared_memory()
# The Ctrl-C tests send SIGINT to the executables they start.  A shell runs a
# background job with SIGINT ignored, and an ignored signal stays ignored across
# exec: the executables would never see it.  With a handler of its own here, the
# children start with the default disposition (exec resets handled signals).
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


#: The modules that take longest (seconds summed over their tests, one local run with
#: two workers: 109, 102, 66, 55, 47, 40, 37, 37, 36, 35 of the suite's 948), longest
#: first.  `make test` hands whole modules to its two workers (``--dist loadfile``) in
#: collection order (``--no-loadscope-reorder``), so these start first and the short
#: ones fill in behind them; picked up last, a long module kept one worker busy for up
#: to a minute and a half after the other had finished.
LONGEST_MODULES = ('test_tune_cli.py', 'test_ros2_cli.py', 'test_pool_restarts.py',
                   'test_pool_hosts.py', 'test_fmu_worker.py', 'test_one_graph_per_domain.py',
                   'test_pareto.py', 'test_graph_one_process.py', 'test_variable_step.py',
                   'test_executables.py')


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Move the tests of :data:`LONGEST_MODULES` to the front, in that order.

    The sort is stable: every module's tests stay together and in their own order.
    """
    rank = {name: i for i, name in enumerate(LONGEST_MODULES)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


#: Run in a child process while the first tests run: a kernel they do not need, which
#: numba compiles on a fresh checkout (single-threaded: the simplified handling model,
#: ~18 s on a shared 2-core machine) and caches; the tests that need it minutes later load it
#: from numba's cache instead of compiling it.  The full model's fixed-step kernel and
#: the simplified ride model are needed within seconds (test_buffers.py,
#: test_calibration_workers.py); the variable-step kernel is left to the session, whose
#: compile of it test_variable_step.py's cache check compares with a cache load.
_WARM_UP = """
import numpy as np
from suspension_tuning import evaluation
from suspension_tuning.vehicle.simplified import SimplifiedInputs, run_simplified
x = np.full((1, 2), 0.5005)
handling = evaluation.evaluate('handling', x)
run_simplified('handling', x, 2, SimplifiedInputs.from_scenario_result(handling.result, 0))
"""


def _kernels_cached() -> bool:
    """Whether numba's cache has an index of the kernel :data:`_WARM_UP` compiles."""
    from pathlib import Path

    from suspension_tuning.vehicle._simplified_kernel import h_integrate

    cache = Path(h_integrate.stats.cache_path)
    return any(cache.glob('_simplified_kernel.h_integrate-*.nbi'))


@pytest.fixture(scope='session', autouse=True)
def _kernels_compiled_beside_the_first_tests():
    """On a fresh checkout, :data:`_WARM_UP` in a child process for the session's start."""
    child = None
    # Under pytest-xdist (`make test`: two workers) the first worker compiles them.
    if os.environ.get('PYTEST_XDIST_WORKER', 'gw0') == 'gw0' and not _kernels_cached():
        child = subprocess.Popen([sys.executable, '-c', _WARM_UP], stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL)
    yield
    if child is not None and child.poll() is None:
        child.kill()
        child.wait()


@pytest.fixture
def executor(ros_executor):
    """The kit's ``ros_executor`` under the name the project's tests use."""
    return ros_executor


@pytest.fixture
def in_process_optimum():
    """``run(options, n_samples, scenario='ride')``: the 2-variable optimisation, in-process.

    Simplified-model gradients scaled by the in-process eq. 25 calibration from
    ``n_samples`` full-model runs, the full model through ``evaluation.evaluate`` (or
    ``model.evaluate``, an FMU model) as in the simulation node (handling: its
    steering and slip angles go to the simplified model, paper 6.1): the bits a run
    through the graph must reach.
    """
    def run(options: dict, n_samples: int, scenario: str = 'ride', model=None):
        from suspension_tuning import evaluation
        from suspension_tuning.optim.simplified_gradient import SimplifiedGradient, calibrate
        from suspension_tuning.tuning import FullEvaluation, TuningRequest, optimise

        evaluate = evaluation.evaluate if model is None else model.evaluate
        scaling = calibrate(scenario, 2, n_samples=n_samples,
                            run_full=lambda name, x: evaluate(name, x).result)

        def full_model(points):
            evaluated = evaluate(scenario, points)
            return FullEvaluation(evaluated.f, evaluated.g, evaluated.result)

        checking = {}
        if model is None:  # the built-in model: the coordinator's noise levels and check
            from suspension_tuning.answer_check import check_options
            from suspension_tuning.tuning import with_noise_levels

            options = with_noise_levels(options, scenario)
            checking = check_options(scenario, 2)
        return optimise(TuningRequest(scenario, 2, None, 'simplified', options), full_model,
                        SimplifiedGradient(scenario, 2, scaling), **checking)
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


FMU_SOURCES = os.path.join(os.path.dirname(__file__), 'fixtures', 'fmu')


@pytest.fixture(scope='session')
def fmus(tmp_path_factory) -> dict[str, str]:
    """The test FMUs, built once per session with pythonfmu from test/fixtures/fmu/.

    ``ride_inputs`` (FMI 2.0, road under each wheel as inputs), ``own_road`` (FMI 3.0,
    a road of its own, declared units), ``failing`` (FMI 2.0, fails mid-run for some
    designs), ``faulty`` (FMI 2.0, raises, returns NaN, hangs, segfaults or exits its
    process mid-run for some designs), ``defender`` (FMI 2.0, the product's own full
    model behind FMI), ``half_car`` (FMI 2.0, a vehicle with names and units of its
    own: cm^3, one road input per axle, no declared units) and ``coil`` (FMI 2.0, a
    coil-sprung vehicle: spring rates in N/mm, damping coefficients in N s/m).
    """
    from pythonfmu.builder import FmuBuilder
    from pythonfmu3.builder import FmuBuilder as Fmu3Builder

    dest = tmp_path_factory.mktemp('fmus')
    plate = [os.path.join(FMU_SOURCES, 'plate_ride.py')]

    def source(name: str) -> str:
        return os.path.join(FMU_SOURCES, name)

    return {
        'ride_inputs': str(FmuBuilder.build_FMU(source('PlateRide.py'), dest=dest,
                                                project_files=plate)),
        'own_road': str(Fmu3Builder.build_FMU(source('PlateOwnRoad3.py'), dest=dest,
                                              project_files=plate)),
        'failing': str(FmuBuilder.build_FMU(source('FailingRide.py'), dest=dest,
                                            project_files=plate)),
        'faulty': str(FmuBuilder.build_FMU(source('FaultyRide.py'), dest=dest,
                                           project_files=plate)),
        'defender': str(FmuBuilder.build_FMU(source('DefenderFmu.py'), dest=dest)),
        'half_car': str(FmuBuilder.build_FMU(source('HalfCarRide.py'), dest=dest,
                                             project_files=plate)),
        'coil': str(FmuBuilder.build_FMU(source('CoilRide.py'), dest=dest,
                                         project_files=plate)),
    }
