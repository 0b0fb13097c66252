"""`ros2 run suspension_tuning <node>` works: the ament index lookup ros2cli does.

ros2cli is not on PyPI, so this test does what `ros2 run` does (ros2/ros2cli
ros2pkg/api and ros2run/api, jazzy): find the package prefix through the ament index
(get_package_prefix), take ``<prefix>/lib/suspension_tuning/<name>``, check it is
executable and start it.  Each node must come up on the graph and stop cleanly on
SIGINT (Ctrl-C).
"""

import os
import signal
import subprocess
import sys
import time
from importlib.metadata import distribution
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros

PACKAGE = 'suspension_tuning'
EXECUTABLES = sorted(ep.name for ep in distribution(PACKAGE).entry_points
                     if ep.group == 'console_scripts')
#: Executables that are ROS nodes and stay up until interrupted (replay exits when its
#: bag is played: tested in test_replay_node.py); the others are command-line tools.
NODES = {name for name in EXECUTABLES
         if (Path(__file__).parents[1] / PACKAGE / 'nodes' / f'{name}.py').exists()} - {'replay'}
TOOLS = sorted(set(EXECUTABLES) - NODES - {'replay'})


def test_package_is_registered_in_the_ament_index():
    from ament_index_python.packages import get_package_prefix, get_package_share_directory

    prefix = Path(get_package_prefix(PACKAGE))
    marker = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / PACKAGE
    assert marker.is_file()
    share = Path(get_package_share_directory(PACKAGE))
    assert (share / 'package.xml').is_file()
    assert (share / 'config' / 'valve_controller.yaml').is_file()


@pytest.mark.parametrize('name', EXECUTABLES)
def test_executable_is_in_lib_and_on_path(name):
    from ament_index_python.packages import get_package_prefix

    path = Path(get_package_prefix(PACKAGE)) / 'lib' / PACKAGE / name
    assert path.is_file() and os.access(path, os.X_OK)
    assert os.access(Path(sys.prefix) / 'bin' / name, os.X_OK)  # on the venv's PATH


@pytest.mark.parametrize('name', sorted(NODES))
def test_node_starts_via_ament_lookup_and_stops_on_sigint(name, ros_context, executor):
    from ament_index_python.packages import get_package_prefix
    from rclpy.node import Node

    path = Path(get_package_prefix(PACKAGE)) / 'lib' / PACKAGE / name
    observer = Node('executable_observer', context=ros_context)
    executor.add(observer)
    process = subprocess.Popen([str(path), '--ros-args', '-r', f'__node:={name}_under_test'],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            # The node serves its parameters: the start-up check's probe of its name
            # (nodes/_unique.py) is on the graph before it, without services.
            if observer.count_services(f'/{name}_under_test/get_parameters'):
                break
            assert process.poll() is None, process.stdout.read()
            time.sleep(0.2)
        else:
            pytest.fail(f'{name} did not appear on the graph within 30 s')
        time.sleep(1.0)  # any other node of the process would be on the graph by now
        names = observer.get_node_names()
    finally:
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=20)
    assert process.returncode == 0, output
    # Each executable is one node: one node of the name, and rcl did not have to
    # share a rosout logger between two of them.
    assert names.count(f'{name}_under_test') == 1, names
    assert 'Publisher already registered' not in output, output


@pytest.mark.parametrize('name', TOOLS)
def test_tool_prints_its_usage(name):
    from ament_index_python.packages import get_package_prefix

    path = Path(get_package_prefix(PACKAGE)) / 'lib' / PACKAGE / name
    run = subprocess.run([str(path), '--help'], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert 'usage' in run.stdout.lower()
