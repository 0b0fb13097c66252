"""``full_vehicle_sim`` running an FMU (``-p model:=fmu``) in the graph.

The worker checks its FMU and mapping at start-up and refuses to start half
configured; a design whose FMU run fails gets an error response naming it and the
worker keeps serving; a 2-variable ride optimisation through the graph with an FMU
worker converges to the in-process bits and its bag names the FMU and the mapping.
"""

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from rclpy.parameter import Parameter
from test_fmu import DEFENDER_RTOL, defender_mapping, failing_mapping, ride_inputs_mapping
from test_graph_simplified import wait

pytestmark = pytest.mark.ros

SAMPLES = 12  # fewer than the paper's 30 to keep the test short; same code path


def write_mapping(tmp_path, mapping, name='mapping.yaml'):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(mapping))
    return str(path)


def fmu_parameters(fmu, mapping_path):
    return [Parameter('model', value='fmu'), Parameter('fmu_path', value=fmu),
            Parameter('fmu_mapping', value=mapping_path)]


def test_fmu_worker_refuses_to_start_half_configured(ros_context, fmus, tmp_path):
    from suspension_tuning.fmu import FmuConfigError, MappingError
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode

    mapping = write_mapping(tmp_path, ride_inputs_mapping())
    cases = [
        ([Parameter('model', value='fmu'), Parameter('fmu_path', value=fmus['ride_inputs'])],
         FmuConfigError, 'model fmu needs fmu_mapping'),
        ([Parameter('fmu_path', value=fmus['ride_inputs'])], FmuConfigError,
         'fmu_path set but model is builtin'),
        ([Parameter('model', value='adams')], FmuConfigError, 'model must be one of'),
        (fmu_parameters(fmus['ride_inputs'], str(tmp_path / 'absent.yaml')), MappingError,
         'absent.yaml: cannot read it'),
        (fmu_parameters(fmus['own_road'], mapping), FmuConfigError,
         "the FMU has no variable 'zRoadFL'"),
    ]
    for params, error, message in cases:
        with pytest.raises(error, match=message):
            FullVehicleSimNode(context=ros_context, parameter_overrides=params)


def test_fmu_worker_executable_says_why_it_does_not_start(fmus, tmp_path):
    """``full_vehicle_sim --ros-args -p model:=fmu`` without a mapping: exit 2, one line."""
    env = {**os.environ, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    done = subprocess.run(
        [sys.executable, '-m', 'suspension_tuning.nodes.full_vehicle_sim', '--ros-args',
         '-p', 'model:=fmu', '-p', f'fmu_path:={fmus["ride_inputs"]}'],
        capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 2, done.stderr
    assert 'full_vehicle_sim: not started: model fmu needs fmu_mapping' in done.stderr
    assert 'Traceback' not in done.stderr


def test_fmu_worker_answers_a_failing_design_with_an_error_and_keeps_serving(
        ros_context, executor, fmus, tmp_path):
    from rclpy.node import Node
    from suspension_tuning_interfaces.srv import EvaluateDesign

    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode

    sim = FullVehicleSimNode(context=ros_context, parameter_overrides=fmu_parameters(
        fmus['failing'], write_mapping(tmp_path, failing_mapping())))
    client_node = Node('fmu_worker_client', context=ros_context)
    executor.add(sim, client_node)
    client = client_node.create_client(EvaluateDesign, '/full_vehicle_sim/evaluate')
    assert client.wait_for_service(timeout_sec=10.0)

    def call(designs, scenario='ride'):
        return wait(client.call_async(EvaluateDesign.Request(
            scenario=scenario, n_vars=2, designs=np.ravel(designs).tolist())), 60.0)

    # x = 0.9 -> dpsf 2.71 > 2.5: the test FMU fails after 0.2 s (test_fmu.py).
    failed = call([[0.3, 0.4], [0.9, 0.4]])
    assert not failed.success
    assert 'design 1 (x = [0.9, 0.4])' in failed.error and 'fmi2DoStep' in failed.error
    assert 'not served' in call([[0.3, 0.4]], 'handling').error
    ok = call([[0.3, 0.4]])
    assert ok.success, ok.error
    assert ok.n_designs == 1 and len(ok.g) == 4
    assert ok.metric_names[:2] == ['a_rms_driver_mps2', 'a_rms_passenger_mps2']


def test_fmu_worker_fails_a_hung_design_at_its_timeout_stops_a_cancelled_one_and_serves_on(
        ros_context, executor, fmus, tmp_path):
    """FaultyRide hanging in a design (test_fmu_isolated.py): the request fails after
    ``fmu_timeout_s`` (given as an int, as users write it) naming the design, the
    simulation time and the FMU's own warning; ``~/cancel`` stops a hung run at once;
    the worker serves the next request."""
    import threading
    import time

    from rclpy.node import Node
    from std_srvs.srv import Trigger
    from suspension_tuning_interfaces.srv import EvaluateDesign
    from test_fmu_isolated import BAD, GOOD, WARNING, faulty_mapping

    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode

    mapping = faulty_mapping(3)  # 3: hang
    sim = FullVehicleSimNode('hung_sim', context=ros_context, parameter_overrides=[
        *fmu_parameters(fmus['faulty'], write_mapping(tmp_path, yaml.safe_load(mapping.text))),
        Parameter('fmu_timeout_s', value=2)])  # 2 s: a healthy design here takes ~0.05 s
    assert sim.get_parameter('fmu_timeout_s').value == 2.0  # stored as the float it means
    client_node = Node('hung_sim_client', context=ros_context)
    executor.add(sim, client_node)
    evaluate = client_node.create_client(EvaluateDesign, '/hung_sim/evaluate')
    cancel = client_node.create_client(Trigger, '/hung_sim/cancel')
    assert evaluate.wait_for_service(timeout_sec=10.0) and cancel.wait_for_service(10.0)

    def send(designs):
        return evaluate.call_async(EvaluateDesign.Request(
            scenario='ride', n_vars=2, designs=np.ravel(designs).tolist()))

    first = wait(send(GOOD), 60.0)  # also waits for the worker's first child process
    assert first.success, first.error
    start = time.monotonic()
    timed_out = wait(send(BAD), 60.0)
    took = time.monotonic() - start
    assert not timed_out.success
    assert ('design 1 (x = [0.9, 0.4]): no result within 2 s (fmu_timeout_s): the FMU hung '
            'at t = 0.202 s') in timed_out.error
    assert WARNING in timed_out.error
    assert took < 2.0 + 5.0  # the bound: within the timeout + 5 s
    # A cancel while the design hangs (its timeout is 2 s away): answered at once.
    warned = threading.Event()
    log = sim.fmu.pool.on_message  # the worker's log of the FMU's messages

    def on_message(message):
        log(message)
        if WARNING in message.text:  # the step after this one hangs
            warned.set()

    sim.fmu.pool.on_message = on_message
    pending = send(BAD)
    assert warned.wait(60.0)
    time.sleep(0.1)  # the next step, the hang, begins within ms
    start = time.monotonic()
    stopped = wait(cancel.call_async(Trigger.Request()), 10.0)
    cancelled = wait(pending, 10.0)
    assert stopped.success, stopped.message
    assert time.monotonic() - start < 2.0  # sooner than the 2 s timeout would end it
    assert cancelled.error.startswith('cancelled: FMU run stopped (cancel requested): '
                                      'design 1 (x = [0.9, 0.4])'), cancelled.error
    assert not wait(cancel.call_async(Trigger.Request()), 10.0).success  # nothing runs
    ok = wait(send(GOOD), 60.0)
    assert ok.success, ok.error
    assert ok.f == first.f


def test_fmu_worker_wrapping_our_full_model_answers_like_the_builtin_worker(
        ros_context, executor, fmus, tmp_path):
    """A handling request with the simplified model's inputs, to a built-in worker and
    to a worker running the product's full model as an FMU: the same f, g, metrics and
    steering and slip-angle histories, within DEFENDER_RTOL (test_fmu.py)."""
    from rclpy.node import Node
    from suspension_tuning_interfaces.srv import EvaluateDesign

    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode

    builtin = FullVehicleSimNode('builtin_sim', context=ros_context)
    fmu = FullVehicleSimNode('fmu_sim', context=ros_context, parameter_overrides=fmu_parameters(
        fmus['defender'], write_mapping(tmp_path, defender_mapping())))
    client_node = Node('fmu_compare_client', context=ros_context)
    executor.add(builtin, fmu, client_node)
    request = EvaluateDesign.Request(scenario='handling', n_vars=2, designs=[0.3, 0.4],
                                     return_inputs=True)
    answers = {}
    for name in ('builtin_sim', 'fmu_sim'):
        client = client_node.create_client(EvaluateDesign, f'/{name}/evaluate')
        assert client.wait_for_service(timeout_sec=10.0)
        answers[name] = wait(client.call_async(request), 120.0)
        assert answers[name].success, answers[name].error
    ours, theirs = answers['fmu_sim'], answers['builtin_sim']
    rtol = DEFENDER_RTOL['handling']
    np.testing.assert_allclose(ours.f, theirs.f, rtol=rtol)
    np.testing.assert_allclose(ours.g, theirs.g, rtol=rtol)
    shared = [n for n in ours.metric_names if n in theirs.metric_names]
    assert len(shared) == len(ours.metric_names) >= 8
    for name in shared:
        np.testing.assert_allclose(ours.metrics[ours.metric_names.index(name)],
                                   theirs.metrics[theirs.metric_names.index(name)],
                                   rtol=rtol, atol=1e-12, err_msg=name)
    mine, built = ours.inputs[0], theirs.inputs[0]
    assert list(mine.names) == list(built.names)  # steering and the four slip angles
    # The FMU samples every communication step (2 ms), the built-in histories every
    # history step: compare on the built-in grid.
    step = int(round(built.dt_s / mine.dt_s))
    data = np.asarray(mine.data).reshape(len(mine.names), -1)[:, ::step]
    reference = np.asarray(built.data).reshape(len(built.names), -1)
    np.testing.assert_allclose(data[:, :reference.shape[1]], reference, rtol=1e-9,
                               atol=1e-12)


def test_ride_optimisation_with_an_fmu_worker_converges_and_its_bag_names_the_fmu(
        ros_context, fmus, tmp_path, in_process_optimum):
    from rclpy.action import ActionClient
    from rclpy.node import Node
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.fmu import FmuModel
    from suspension_tuning.graph import SpinningGraph, build_nodes
    from suspension_tuning.inspect_bag import summary
    from suspension_tuning.nodes.coordinator import CoordinatorNode

    mapping_path = write_mapping(tmp_path, ride_inputs_mapping())
    nodes = build_nodes(workers=1, record=True, context=ros_context, overrides={
        'full_vehicle_sim': fmu_parameters(fmus['ride_inputs'], mapping_path),
        'gradient_evaluator': [Parameter('calibration_dir', value=str(tmp_path / 'cal'))],
        'coordinator': [Parameter('calibration_samples', value=SAMPLES)],
        'recorder': [Parameter('output_dir', value=str(tmp_path / 'bags')),
                     Parameter('discovery_period_s', value=0.1)]})
    coordinator = next(n for n in nodes if isinstance(n, CoordinatorNode))
    client_node = Node('fmu_graph_client', context=ros_context)
    graph = SpinningGraph(nodes, [client_node])
    try:
        client = ActionClient(client_node, Optimise, '/coordinator/optimise')
        assert client.wait_for_server(timeout_sec=10.0)
        handle = wait(client.send_goal_async(
            Optimise.Goal(scenario='ride', n_vars=2, gradient_source='simplified')), 30.0)
        result = wait(handle.get_result_async()).result
        options = coordinator.options.as_dict()
    finally:
        graph.shutdown()  # the recorder closes the run's bag
    assert result.success, result.message
    assert result.n_calibration_runs == SAMPLES
    # The same loop in-process on the same FMU: the same bits.
    with FmuModel(fmus['ride_inputs'], mapping_path) as fmu:
        local = in_process_optimum(options, SAMPLES, model=fmu)
        guid = fmu.description()['guid']
    # The same optimum to round-off.  On the sett paving the worker's run and the
    # in-process run of this FMU differ in the last bits of x (1e-15, from 12
    # iterations); the built-in worker reaches the in-process bits exactly
    # (test_graph_simplified.py).
    # the reported (best) design
    np.testing.assert_allclose(result.x, local.x_best, rtol=1e-12, atol=1e-14)
    assert result.f == pytest.approx(local.f_best, rel=1e-12)
    assert local.status in (0, 1), local.message  # converged (dynamic_q.STATUS_MESSAGES)
    bags = sorted(Path(tmp_path / 'bags').iterdir())
    assert len(bags) == 1, bags
    config = summary(bags[0])['run_config']
    model = config['simulation_models']['/full_vehicle_sim']
    assert model['model'] == 'fmu' and model['fmu_file'] == 'PlateRide.fmu'
    assert (model['fmu_isolation'], model['fmu_timeout_s']) == ('process', 300.0)  # defaults
    assert model['guid'] == guid
    assert model['fmu_mapping'] == mapping_path
    assert yaml.safe_load(model['mapping']) == ride_inputs_mapping()


def test_fmu_graph_fails_a_hung_goal_stops_a_cancelled_one_serves_on_and_stops_on_sigterm(
        ros_context, executor, fmus, tmp_path):
    """``graph`` with a worker whose FMU hangs for some designs (FaultyRide, fault 3):
    the hung goal fails at ``fmu_timeout_s`` naming the design, a cancelled one ends at
    once, the next goal succeeds as before, and SIGTERM during a hang stops the graph
    within 5 s with every bag complete."""
    import signal
    import threading
    import time

    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient
    from rclpy.node import Node
    from suspension_tuning_interfaces.action import Optimise
    from test_fmu_isolated import WARNING, faulty_mapping

    from suspension_tuning.testing import open_bag

    params = tmp_path / 'graph.yaml'
    params.write_text(yaml.safe_dump({
        '/**/full_vehicle_sim': {'ros__parameters': {
            'model': 'fmu', 'fmu_path': fmus['faulty'],
            'fmu_mapping': write_mapping(tmp_path, yaml.safe_load(faulty_mapping(3).text)),
            'fmu_timeout_s': 2}},  # 2 s: a healthy design here takes ~0.05 s
        # 30 as users write it (an int for a float parameter)
        '/**/coordinator': {'ros__parameters': {'design_timeout_s': 30,
                                                'final_telemetry': False}},
        '/**/recorder': {'ros__parameters': {'output_dir': str(tmp_path / 'bags')}}}))
    graph = subprocess.Popen([str(Path(sys.prefix) / 'bin' / 'graph'), '--ros-args',
                              '--params-file', str(params)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    graph_err: list[str] = []  # drained as it comes: a full pipe would block the graph
    drain = threading.Thread(target=lambda: graph_err.extend(graph.stderr), daemon=True)
    drain.start()
    try:
        client_node = Node('fmu_graph_goals', context=ros_context)
        executor.add(client_node)
        client = ActionClient(client_node, Optimise, '/coordinator/optimise')
        assert client.wait_for_server(timeout_sec=60.0), ''.join(graph_err)

        def send(x0):  # full gradients: no calibration, whose samples span every design
            return wait(client.send_goal_async(Optimise.Goal(
                scenario='ride', n_vars=2, x0=x0, gradient_source='full', max_iterations=1,
                move_limit=0.1)), 30.0)  # x stays below 0.83 (dpsf 2.5, eq. 4) from 0.3

        def result(handle, timeout_s=60.0):
            return wait(handle.get_result_async(), timeout_s)

        def hanging(x0):  # a goal whose first design hangs: sent, and in the hang
            before = ''.join(graph_err).count(WARNING)
            handle = send(x0)
            deadline = time.monotonic() + 60.0
            while ''.join(graph_err).count(WARNING) == before:  # logged just before
                assert time.monotonic() < deadline, ''.join(graph_err)
                time.sleep(0.05)
            time.sleep(0.1)  # the next step, the hang, begins within ms
            return handle

        good = result(send([0.3, 0.4]))  # also waits for the worker's first child process
        assert good.status == GoalStatus.STATUS_SUCCEEDED, good.result.message
        # x0 = 0.9: dpsf 2.71 > 2.5, the first design hangs after 0.2 s of FMU time.
        start = time.monotonic()
        hung = result(send([0.9, 0.4]))
        assert time.monotonic() - start < 2.0 + 5.0  # the bound: timeout + 5 s
        assert hung.status == GoalStatus.STATUS_ABORTED
        assert ('design 0 (x = [0.9, 0.4]): no result within 2 s (fmu_timeout_s): the FMU '
                'hung at t = 0.202 s') in hung.result.message
        assert WARNING in hung.result.message
        # A cancel reaches the hung run: the goal ends at once, not at the timeout.
        handle = hanging([0.9, 0.4])
        start = time.monotonic()
        wait(handle.cancel_goal_async(), 10.0)
        cancelled = result(handle)
        assert time.monotonic() - start < 2.0  # sooner than the 2 s timeout would end it
        assert cancelled.status == GoalStatus.STATUS_CANCELED, cancelled.result.message
        again = result(send([0.3, 0.4]))  # the same worker serves the next goal
        assert again.status == GoalStatus.STATUS_SUCCEEDED, again.result.message
        assert again.result.f == good.result.f
        # SIGTERM while a design hangs.
        hanging([0.9, 0.4])
        start = time.monotonic()
        graph.send_signal(signal.SIGTERM)
        try:
            graph.wait(timeout=30)
        except subprocess.TimeoutExpired:
            pass  # said below, with the graph's log
        stopped_s = time.monotonic() - start
    finally:
        if graph.poll() is None:
            graph.kill()
        drain.join(timeout=10)
    log = ''.join(graph_err)
    assert stopped_s < 5.0, log
    assert graph.returncode == 0, log
    assert 'Traceback' not in log, log
    # The FMU's own words in the worker's log, and the cancel reaching the run.
    assert f'FMU, design 0, t = 0.2 s: [warning] logStatusWarning: {WARNING}' in log, log
    assert 'cancelled: FMU run stopped (cancel requested): design 0' in log, log
    bags = sorted((tmp_path / 'bags').iterdir())
    assert len(bags) == 5, bags  # one per goal, the last one cut by SIGTERM
    for bag in bags:
        assert open_bag(bag).message_count > 0  # raises unless complete


def test_fmu_graph_with_a_junk_fmu_says_why_in_one_line_and_exits_2(tmp_path):
    """``graph`` as the worker alone (test_fmu_worker_executable_says_why_it_does_not_start)."""
    junk = tmp_path / 'junk.fmu'
    junk.write_bytes(b'not a zip file')
    mapping = write_mapping(tmp_path, ride_inputs_mapping())
    env = {**os.environ, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    done = subprocess.run([str(Path(sys.prefix) / 'bin' / 'graph'), '--no-record',
                           '--ros-args', '-p', 'model:=fmu', '-p', f'fmu_path:={junk}',
                           '-p', f'fmu_mapping:={mapping}'],
                          capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith('full_vehicle_sim: not started: junk.fmu: not a readable '
                                  'FMU'), done.stderr
    assert 'Traceback' not in done.stderr and done.stderr.count('\n') == 1, done.stderr


def test_fmu_worker_says_what_its_plausibility_run_waits_for_and_a_hang_is_bounded(
        ros_context, fmus, tmp_path, monkeypatch, capfd):
    """A start-up plausibility run that hangs: the log names the run and its limit
    first; the run is stopped at plausibility_timeout_s (not fmu_timeout_s, 300 s) with
    a warning, and the worker serves."""
    import shutil

    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode
    from suspension_tuning.paths import CONFIG_DIR_VARIABLE, config_dir

    # FaultyRide hangs for a damper scale above 2.5 after 0.2 s: a design space of
    # dpsf 2.6-3.0 puts the centre design (the check's run) at 2.8.
    config = tmp_path / 'config'
    shutil.copytree(config_dir(), config)
    space = config / 'design_space.yaml'
    space.write_text(space.read_text().replace('{low: 0.1, high: 3.0, baseline: 1.0}',
                                               '{low: 2.6, high: 3.0, baseline: 2.8}'))
    monkeypatch.setenv(CONFIG_DIR_VARIABLE, str(config))
    mapping = failing_mapping()
    mapping['scenarios']['ride'].update(stop_time_s=1.0, settle_s=0.5,
                                        parameters={'fault': 3})  # 3: hang
    limit_s = 3.0
    params = [*fmu_parameters(fmus['faulty'], write_mapping(tmp_path, mapping)),
              Parameter('plausibility_check', value='always'),
              Parameter('plausibility_timeout_s', value=limit_s)]
    capfd.readouterr()
    start = time.monotonic()
    node = FullVehicleSimNode(context=ros_context, parameter_overrides=params)
    try:
        elapsed = time.monotonic() - start
        log = capfd.readouterr().err
        warnings = node.model_description['plausibility']['warnings']
        assert node.evaluate_service is not None  # it serves
    finally:
        node.destroy_node()
    said = [line for line in log.splitlines() if 'plausibility' in line]
    assert said[0].endswith('plausibility check: one run of the centre design in ride, at '
                            'most 3 s in all (plausibility_timeout_s, fmu_timeout_s); the '
                            'worker serves once it ends'), log
    assert ('ride: the run of the centre design failed (design 0 (x = [0.5, 0.5]): no result '
            "within 3 s (the plausibility check's limit, plausibility_timeout_s): the FMU "
            'hung at t = 0.202 s') in warnings[0]
    # The limit plus the child process's load of the FMU (3-15 s measured, isolated.py
    # START_TIMEOUT_S), far below fmu_timeout_s (300 s).
    assert elapsed < limit_s + 60.0
