"""The upstream ``ros2`` command line against ``graph``: the verbs a user tries first.

ros2cli is not on PyPI; ``../shared/tools/ros2cli/install.sh`` (beside the clone, as
in CI) installs the upstream sources (branch jazzy): ``make test`` into build/ros2cli
(:data:`PREBUILT`), else this module into a directory of its own.  One ``graph
--telemetry-rate 1.0`` (live telemetry) serves every test here, on the session's
domain.  ``--no-daemon`` verbs discover the graph for ``--spin-time`` seconds:
Fast DDS discovery on a loaded machine needs a few (3 s was seen to miss
the latched result topic and to leave a parameter call unanswered for 60 s).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
INSTALL = ROOT.parent / 'shared' / 'tools' / 'ros2cli' / 'install.sh'
#: ros2cli as ``make test`` installs it (Makefile, ``$(STAMPS)/ros2cli``), for this venv.
PREBUILT = ROOT / 'build' / 'ros2cli'
BIN = Path(sys.executable).parent
NODES = ['/coordinator', '/full_vehicle_sim', '/gradient_evaluator', '/recorder',
         '/valve_controller']
SPIN = ['--no-daemon', '--spin-time', '5']
#: Live telemetry's rate factor here: the 30 s ride run (config/scenarios.yaml) in 10 s.
RATE_FACTOR = 3.0
#: Telemetry rate per topic at factor 1.0, Hz: histories at 250 Hz (config/vehicle.yaml
#: history_decimation 2 of the 500 Hz steps), every 2nd published (config/graph.yaml
#: telemetry_decimation 2).
LIVE_RATE_HZ = 125.0

pytestmark = [
    pytest.mark.ros,
    pytest.mark.skipif(not INSTALL.is_file(),
                       reason=f'no ros2cli to test with: {INSTALL} is absent (the shared '
                              'tools directory beside the clone; CI has it)'),
]


def _prebuilt_for_this_venv() -> bool:
    """Whether build/ros2cli holds a ``ros2`` whose interpreter is this venv's python."""
    script = PREBUILT / 'bin' / 'ros2'
    if not script.is_file():
        return False
    first = script.read_text(encoding='utf-8', errors='replace').split('\n', 1)[0]
    return first == f'#!{sys.executable}'


@pytest.fixture(scope='module')
def ros2(tmp_path_factory, ros_domain_id):
    """``ros2(*args, timeout=60)``: run the upstream ros2 command, its CompletedProcess."""
    target = PREBUILT
    if not _prebuilt_for_this_venv():
        target = tmp_path_factory.mktemp('ros2cli')
        subprocess.run([str(INSTALL), str(target), sys.executable], check=True,
                       capture_output=True, text=True, timeout=600)
    env = {**os.environ, 'PYTHONPATH': str(target),
           'PATH': f'{BIN}{os.pathsep}{os.environ.get("PATH", "")}',
           'ROS_DOMAIN_ID': str(ros_domain_id), 'PYTHONUNBUFFERED': '1'}

    def run(*args: str, timeout: float = 60.0, **kwargs) -> subprocess.CompletedProcess:
        return subprocess.run([str(target / 'bin' / 'ros2'), *args], env=env,
                              capture_output=True, text=True, timeout=timeout, **kwargs)

    def many(*commands: list[str], timeout: float = 60.0) -> list[tuple[str, str]]:
        """Run several ros2 commands at once; (stdout, stderr) of each."""
        processes = [subprocess.Popen([str(target / 'bin' / 'ros2'), *args], env=env,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      text=True) for args in commands]
        return [p.communicate(timeout=timeout) for p in processes]

    run.env = env
    run.command = str(target / 'bin' / 'ros2')
    run.many = many
    return run


@pytest.fixture(scope='module')
def graph(ros2, tmp_path_factory):
    """``graph`` with live telemetry, up (the coordinator serving), stopped by SIGINT after."""
    bags = tmp_path_factory.mktemp('bags')
    process = subprocess.Popen([str(BIN / 'graph'), '--telemetry-rate', str(RATE_FACTOR),
                                '--ros-args',
                                '-p', f'output_dir:={bags}'], env=ros2.env,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 90
        # (Not ``ros2 action list``: without --no-daemon it would start ros2's daemon.)
        while '/coordinator/get_parameters' not in ros2('service', 'list', *SPIN).stdout:
            assert process.poll() is None, process.stdout.read()
            assert time.monotonic() < deadline, 'graph did not come up within 90 s'
            time.sleep(1.0)
        process.bags = bags
        yield process
    finally:
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=30)
    # Ctrl-C ends graph cleanly (docs/distributed.md), every bag closed.
    assert process.returncode == 0, output
    for mcap in bags.rglob('*.mcap'):
        assert mcap.read_bytes().endswith(b'\x89MCAP0\r\n'), mcap


def test_pkg_lists_the_executables(ros2):
    out = ros2('pkg', 'executables', 'suspension_tuning').stdout
    for name in ('graph', 'coordinator', 'full_vehicle_sim', 'gradient_evaluator',
                 'valve_controller', 'recorder', 'replay', 'tune', 'inspect_bag'):
        assert f'suspension_tuning {name}\n' in out, out


def test_interface_show_resolves_every_interface(ros2):
    names = ros2('interface', 'package', 'suspension_tuning_interfaces').stdout.split()
    assert 'suspension_tuning_interfaces/msg/OptimisationResult' in names
    for name in names:
        shown = ros2('interface', 'show', name)
        assert shown.returncode == 0 and shown.stdout.strip(), (name, shown.stderr)


def test_node_list_and_info_show_the_graph(ros2, graph):
    listed = ros2('node', 'list', *SPIN).stdout.split()
    assert set(NODES) <= set(listed), listed
    info = ros2('node', 'info', '/coordinator', *SPIN).stdout
    assert '/coordinator/optimise: suspension_tuning_interfaces/action/Optimise' in info
    assert '/optimisation/result: suspension_tuning_interfaces/msg/OptimisationResult' in info


def test_param_dump_of_every_node_lists_its_parameters(ros2, graph):
    dumps = ros2.many(*[['param', 'dump', node, *SPIN] for node in NODES])
    for node, (out, err) in zip(NODES, dumps):
        assert f'{node}:\n  ros__parameters:\n' in out, (node, out, err)
        assert 'use_sim_time: false' in out, (node, out, err)
    coordinator = dumps[0][0]
    assert 'sim_workers: []' in coordinator, coordinator  # every worker (the default)
    assert 'telemetry_rate: 3.0' in dumps[1][0], dumps[1][0]  # graph --telemetry-rate


def test_param_set_refuses_a_start_up_parameter_and_takes_a_live_one(ros2, graph):
    refused, taken = ros2.many(['param', 'set', '/coordinator', 'result_timeout_s', '20', *SPIN],
                               ['param', 'set', '/coordinator', 'fd_step', '0.03', *SPIN])
    assert 'read-only' in refused[0] + refused[1], refused
    assert 'Set parameter successful' in taken[0], taken


def test_service_call_refuses_nan_with_the_number_as_text(ros2, graph):
    call = ros2('service', 'call', '/full_vehicle_sim/evaluate',
                'suspension_tuning_interfaces/srv/EvaluateDesign',
                "{scenario: ride, n_vars: 2, designs: [.nan, 0.5]}")
    assert call.returncode == 0, call.stderr
    assert 'success=False' in call.stdout, call.stdout
    assert 'is not finite: nan' in call.stdout and 'np.float64' not in call.stdout, call.stdout


def test_live_telemetry_is_paced_and_every_latched_topic_echoes(ros2, graph):
    hz = subprocess.Popen([ros2.command, 'topic', 'hz', '/full_vehicle_sim/telemetry/imu'],
                          env=ros2.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                          text=True)
    try:
        time.sleep(4.0)  # hz subscribed
        goal = ros2('action', 'send_goal', '--feedback', '/coordinator/optimise',
                    'suspension_tuning_interfaces/action/Optimise',
                    '{scenario: ride, n_vars: 2, gradient_source: evaluate}', timeout=180)
    finally:
        hz.send_signal(signal.SIGINT)
        rates, _ = hz.communicate(timeout=30)
    assert 'Goal finished with status: SUCCEEDED' in goal.stdout, goal.stdout + goal.stderr
    # Live: hz saw the run's messages as they came.  Paced at simulated time /
    # RATE_FACTOR: never faster than the configured rate (20 % for hz's windowing; an
    # unpaced run, all at once, arrives at about 1,500 Hz: bench_telemetry.py --factor
    # 0).  How close to the configured rate the stream comes is a speed figure, and
    # depends on the machine's load: benchmarks/bench_telemetry.py measures it.
    averages = [float(v) for v in re.findall(r'average rate: ([0-9.]+)', rates)]
    assert averages, rates
    configured = LIVE_RATE_HZ * RATE_FACTOR
    assert 0.0 < averages[-1] < 1.2 * configured, rates[-500:]
    latched = {'/optimisation/result': 'evaluated: one full-model run',
               '/optimisation/run_config': 'scenario: ride',
               '/full_vehicle_sim/model': 'model: builtin'}
    echoes = ros2.many(*[['topic', 'echo', '--once', topic, *SPIN] for topic in latched])
    for (topic, expected), (out, err) in zip(latched.items(), echoes):
        assert expected in out, (topic, out, err)


def test_run_adds_a_worker_that_the_coordinator_takes(ros2, graph):
    # A session of its own: Ctrl-C reaches ``ros2 run`` and the node it runs alike.
    worker = subprocess.Popen([ros2.command, 'run', 'suspension_tuning', 'full_vehicle_sim',
                               '--ros-args', '-r', '__node:=sim_x'], env=ros2.env,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                              start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        while '/sim_x' not in ros2('node', 'list', *SPIN).stdout.split():
            assert worker.poll() is None, worker.stdout.read()
            assert time.monotonic() < deadline, 'sim_x not on the graph within 60 s'
        topics = ros2('topic', 'list', '-t', *SPIN).stdout
        assert '/sim_x/telemetry/imu [sensor_msgs/msg/Imu]' in topics, topics
        services = ros2('service', 'list', *SPIN).stdout
        assert '/sim_x/evaluate' in services, services
    finally:
        os.killpg(worker.pid, signal.SIGINT)
        output, _ = worker.communicate(timeout=30)
    assert worker.returncode == 0, output
