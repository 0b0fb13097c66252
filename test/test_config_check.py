"""Configuration files are checked when a node or command starts, in one line naming file
and key (suspension_tuning.config_check)."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from suspension_tuning.config_check import ConfigError, check_config, check_design_space
from suspension_tuning.paths import CONFIG_DIR_VARIABLE, config_dir

SPRING_FRONT = 'front: {low: 0.1, high: 0.6, baseline: 0.3}'


@pytest.fixture
def config_copy(tmp_path, monkeypatch):
    """A copy of config/ that the check (and any program started here) reads."""
    folder = tmp_path / 'config'
    shutil.copytree(config_dir(), folder)
    monkeypatch.setenv(CONFIG_DIR_VARIABLE, str(folder))
    return folder


def _edit(folder: Path, name: str, old: str, new: str) -> None:
    path = folder / name
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


# (old text of config/design_space.yaml's spring section, new text, the line's start)
DESIGN_SPACE_CASES = {
    'lower above upper': (SPRING_FRONT, 'front: {low: 0.7, high: 0.6, baseline: 0.3}',
                          'spring.front: need 0 < low < high, got low 0.7 and high 0.6 L'),
    'negative gas volume': (SPRING_FRONT, 'front: {low: -0.1, high: 0.6, baseline: 0.3}',
                            'spring.front: need 0 < low < high, got low -0.1'),
    'zero-width range': (SPRING_FRONT, 'front: {low: 0.3, high: 0.3, baseline: 0.3}',
                         'spring.front: need 0 < low < high, got low 0.3 and high 0.3'),
    'baseline outside its range': (SPRING_FRONT, 'front: {low: 0.1, high: 0.6, baseline: 0.9}',
                                   'spring.front.baseline: 0.9 lies outside 0.1-0.6 L'),
    'missing baseline': (SPRING_FRONT, 'front: {low: 0.1, high: 0.6}',
                         'spring.front: expected {low: ..., high: ..., baseline: ...}'),
    'number written as text': (SPRING_FRONT, "front: {low: 0.1, high: '0.6', baseline: 0.3}",
                               "spring.front.high: expected a finite number, got '0.6'"),
    'unknown quantity': ('quantity: volume ', 'quantity: mass ',
                         "spring.quantity: 'mass' is not one of"),
    'unit of another quantity': ('  unit: L', '  unit: N/m',
                                 "spring.unit: 'N/m' is not a unit of volume"),
    'missing key': ('  unit: L\n', '\n', "spring: missing key(s) ['unit']"),
    'YAML syntax error': ('damper:', 'damper: [', 'not valid YAML at line '),
}


@pytest.mark.parametrize('case', list(DESIGN_SPACE_CASES))
def test_a_bad_design_space_is_named_by_file_and_key(config_copy, case):
    old, new, start = DESIGN_SPACE_CASES[case]
    _edit(config_copy, 'design_space.yaml', old, new)
    with pytest.raises(ConfigError) as raised:
        check_design_space()
    assert str(raised.value).startswith(f'config/design_space.yaml: {start}')
    assert '\n' not in str(raised.value)


def test_a_coil_spring_is_refused_for_the_built_in_gas_spring_model_only(config_copy):
    _edit(config_copy, 'design_space.yaml', 'quantity: volume ', 'quantity: stiffness ')
    _edit(config_copy, 'design_space.yaml', '  unit: L', '  unit: kN/m')
    _edit(config_copy, 'design_space.yaml', SPRING_FRONT,
          'front: {low: 20, high: 80, baseline: 48}')
    _edit(config_copy, 'design_space.yaml', 'rear: {low: 0.1, high: 0.6, baseline: 0.3}',
          'rear: {low: 20, high: 80, baseline: 48}')
    check_design_space(builtin_model=False)  # an FMU of a coil-sprung vehicle takes it
    with pytest.raises(ConfigError, match=r"^config/design_space.yaml: spring.quantity: "
                                          r"'stiffness' \(a coil-spring rate\) needs"):
        check_design_space(builtin_model=True)


def test_the_shipped_configuration_passes(monkeypatch):
    monkeypatch.delenv(CONFIG_DIR_VARIABLE, raising=False)
    check_config(builtin_model=True)


def test_a_missing_key_or_a_number_as_text_in_the_vehicle_is_named(config_copy):
    # (loads the vehicle through the module constant of the package's folder: the
    # loaders are run on a copy of it in a subprocess, as a node would)
    def check() -> str:
        run = subprocess.run(
            [sys.executable, '-c', 'from suspension_tuning.config_check import check_config\n'
             'check_config()'], capture_output=True, text=True, timeout=120,
            env=os.environ.copy())
        assert run.returncode == 1
        return run.stderr.strip().splitlines()[-1]

    original = (config_copy / 'vehicle.yaml').read_text()
    _edit(config_copy, 'vehicle.yaml', '  wheelbase_m:', '  wheelbase_mm:')
    assert check().endswith('ConfigError: config/vehicle.yaml: missing key '
                            'geometry.wheelbase_m')
    (config_copy / 'vehicle.yaml').write_text(original)
    _edit(config_copy, 'vehicle.yaml', '  cg_height_m: 0.95', "  cg_height_m: 'about 0.95'")
    assert check().endswith("ConfigError: config/vehicle.yaml: geometry.cg_height_m: expected "
                            "a number, could not convert string to float: 'about 0.95'")


@pytest.mark.parametrize('line, bad, message', [
    ('continue_by: tighter_model', 'continue_by: model',
     "integration.check.continue_by must be one of shift, tighter_model, got 'model'"),
    ('last_iterate_gap: 0.01', 'last_iterate_gap: -0.01',
     'integration.check.last_iterate_gap must be >= 0 and finite, got -0.01'),
    ('refine_noise_stop: true', 'refine_noise_stop: 1',
     'integration.check.refine_noise_stop must be true or false, got 1'),
])
def test_a_bad_setting_of_the_answer_check_is_named(config_copy, line, bad, message):
    _edit(config_copy, 'vehicle.yaml', line, bad)
    with pytest.raises(ConfigError) as raised:
        check_config()
    assert str(raised.value) == f'config/vehicle.yaml: {message}'


@pytest.mark.ros
def test_graph_with_a_bad_config_file_does_not_start_one_line_exit_2(config_copy):
    _edit(config_copy, 'design_space.yaml', SPRING_FRONT,
          'front: {low: 0.7, high: 0.6, baseline: 0.3}')
    graph = Path(sys.prefix) / 'bin' / 'graph'
    run = subprocess.run([str(graph), '--no-record'], capture_output=True, text=True,
                         timeout=120, env=os.environ.copy())
    assert run.returncode == 2
    assert run.stderr.strip() == ('full_vehicle_sim: not started: config/design_space.yaml: '
                                  'spring.front: need 0 < low < high, got low 0.7 and high '
                                  '0.6 L')


@pytest.mark.ros
def test_a_worker_of_the_built_in_model_refuses_a_coil_spring_and_yaml_errors(config_copy):
    _edit(config_copy, 'scenarios.yaml', 'ride:', 'ride: [')
    worker = Path(sys.prefix) / 'bin' / 'full_vehicle_sim'
    run = subprocess.run([str(worker)], capture_output=True, text=True, timeout=120,
                         env=os.environ.copy())
    assert run.returncode == 2
    [line] = run.stderr.strip().splitlines()
    assert line.startswith('full_vehicle_sim: not started: config/scenarios.yaml: not valid '
                           'YAML at line ')


def test_tune_start_with_a_yaml_error_says_so_in_one_line(config_copy):
    _edit(config_copy, 'design_space.yaml', 'damper:', 'damper: [')
    tune = Path(sys.prefix) / 'bin' / 'tune'
    run = subprocess.run([str(tune), '--start', 'dpsf=1.2', 'gas_volume_l=0.35'],
                         capture_output=True, text=True, timeout=120, env=os.environ.copy())
    assert run.returncode == 2
    [line] = run.stderr.strip().splitlines()
    assert line.startswith('error: ') and 'design_space.yaml: not valid YAML at line' in line


@pytest.mark.parametrize('command', ['graph', 'coordinator', 'tune'])
def test_a_parameter_file_with_a_yaml_error_is_refused_in_one_line(command, tmp_path):
    params = tmp_path / 'params.yaml'
    params.write_text('/**:\n  ros__parameters:\n    design_timeout_s: [360\n')
    run = subprocess.run([str(Path(sys.prefix) / 'bin' / command), '--ros-args',
                          '--params-file', str(params)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    [line] = run.stderr.strip().splitlines()
    assert line.endswith(f'--params-file {params}: not valid YAML at line 4, column 1: '
                         "expected ',' or ']', but got '<stream end>'"), line


@pytest.mark.ros
def test_a_goal_after_a_config_file_broke_reports_the_files_line_first(
        config_copy, ros_context, executor):
    from rclpy.action import ActionClient
    from rclpy.node import Node
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.nodes.coordinator import CoordinatorNode
    from suspension_tuning.testing import wait_for_future as wait

    coordinator = CoordinatorNode(context=ros_context)  # starts on the valid copy
    client_node = Node('config_goal_client', context=ros_context)
    executor.add(coordinator, client_node)
    _edit(config_copy, 'design_space.yaml', SPRING_FRONT,
          'front: {low: 0.1, high: 0.6, baseline: 0.9}')  # edited while it runs
    client = ActionClient(client_node, Optimise, '/coordinator/optimise')
    assert client.wait_for_server(timeout_sec=10.0)
    handle = wait(client.send_goal_async(Optimise.Goal(scenario='ride', n_vars=2)), 30.0)
    result = wait(handle.get_result_async(), 60.0).result
    assert not result.success
    assert result.message == ('configuration: config/design_space.yaml: '
                              'spring.front.baseline: 0.9 lies outside 0.1-0.6 L')
