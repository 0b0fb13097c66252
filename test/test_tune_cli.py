"""`tune` sends a goal, prints progress per iteration and the optimum in physical units."""

import os
import subprocess
import sys
from pathlib import Path

import pytest
from rclpy.parameter import Parameter

pytestmark = pytest.mark.ros


def _serve_coordinator(ros_context, executor) -> None:
    """A simulation worker and a coordinator (no telemetry run), spun by ``executor``."""
    from suspension_tuning.nodes.coordinator import CoordinatorNode
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode

    executor.add(FullVehicleSimNode(context=ros_context),
                 CoordinatorNode(context=ros_context, parameter_overrides=[
                     Parameter('final_telemetry', value=False)]))


def test_tune_prints_progress_and_the_physical_optimum(ros_context, executor):
    _serve_coordinator(ros_context, executor)
    tune = Path(sys.prefix) / 'bin' / 'tune'
    run = subprocess.run([str(tune), '--scenario', 'handling', '--n-vars', '2',
                          '--gradient', 'full', '--max-iterations', '2'],
                         capture_output=True, text=True, timeout=300, env=os.environ.copy())
    out = run.stdout
    assert 'iteration   0' in out and 'max violation' in out, out + run.stderr
    assert 'optimum in physical units' in out
    assert 'gas_volume_front_l' in out and 'dpsf_front' in out
    assert 'full-model runs:' in out


def _result(feasible: bool, best_iteration: int, max_violation: float):
    """An action result of three iterations whose design is that of ``best_iteration``."""
    from suspension_tuning_interfaces.action import Optimise
    from suspension_tuning_interfaces.msg import IterationRecord

    history = [IterationRecord(iteration=k, f=1.0 - 0.25 * k) for k in range(3)]
    return Optimise.Result(
        success=feasible, message='...', x=[0.5, 0.5], f=history[best_iteration].f,
        g=[max_violation - 0.5, max_violation], feasible=feasible,
        best_iteration=best_iteration, max_violation=max_violation,
        physical_names=['dpsf_front', 'gas_volume_front_l'], physical_values=[1.5, 0.35],
        iterations=2, history=history)


def test_tune_prints_the_best_feasible_design_as_the_optimum_with_its_iteration():
    from suspension_tuning.tune import format_result

    text = format_result(_result(True, 1, 0.0))  # iteration 1 best, 2 last (infeasible)
    assert 'optimum: the best feasible design, iteration 1 (max violation 0)' in text
    assert 'f: 0.750000' in text  # history[1].f = 1 - 0.25
    assert 'last iterate: iteration 2, f = 0.500000' in text
    assert 'optimum in physical units:' in text and 'dpsf_front: 1.5' in text


def test_tune_says_plainly_when_no_design_was_feasible():
    from suspension_tuning.tune import format_result

    text = format_result(_result(False, 0, 0.25))  # iteration 0 violates least, g = 0.25
    assert ('no feasible design found: the reported design is the least violating one '
            '(max g = 0.25), iteration 0') in text
    assert 'optimum' not in text
    assert 'least violating design in physical units (not feasible):' in text


def test_tune_sends_constraints_from_the_command_line(ros_context, executor):
    _serve_coordinator(ros_context, executor)
    tune = Path(sys.prefix) / 'bin' / 'tune'
    run = subprocess.run([str(tune), '--scenario', 'ride', '--gradient', 'full',
                          '--max-iterations', '2', '--constraint', 'handling:f_hand<=1.2',
                          '--constraint', 'handling:roll_first_peak_deg<=5'],
                         capture_output=True, text=True, timeout=300, env=os.environ.copy())
    assert run.returncode in (0, 1), run.stderr  # 2 iterations may stop unconverged
    # Full-model gradients were asked for: every term is differenced on the full model.
    assert 'constraint 0: value' in run.stdout and '(gradient: full)' in run.stdout
    assert 'constraint 1: value' in run.stdout, run.stdout + run.stderr


def test_tune_telemetry_rate_sets_the_workers_live_for_its_goal_and_back_after(
        ros_context, executor):
    from suspension_tuning.nodes.coordinator import CoordinatorNode
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode

    worker = FullVehicleSimNode(context=ros_context)
    seen: list[float] = []  # every telemetry_rate the worker was set to
    worker.add_post_set_parameters_callback(lambda params: seen.extend(
        p.value for p in params if p.name == 'telemetry_rate'))
    executor.add(worker, CoordinatorNode(context=ros_context, parameter_overrides=[
        Parameter('final_telemetry', value=False)]))
    tune = Path(sys.prefix) / 'bin' / 'tune'
    # One handling run (8.9 s of lane change at 4 x: about 2 s of pacing).
    run = subprocess.run([str(tune), '--scenario', 'handling', '--evaluate',
                          '--telemetry-rate', '4'],
                         capture_output=True, text=True, timeout=300, env=os.environ.copy())
    assert run.returncode == 0, run.stdout + run.stderr
    assert 'live telemetry at 4 x simulated time from /full_vehicle_sim' in run.stderr
    assert seen == [4.0, 0.0]  # set for the goal, then back to the default 0 (at once)
    assert worker.get_parameter('telemetry_rate').value == 0.0


def test_tune_rejects_a_malformed_constraint_before_sending_a_goal():
    tune = Path(sys.prefix) / 'bin' / 'tune'
    run = subprocess.run([str(tune), '--constraint', 'handling:f_hand<0.8'],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert "expected '<scenario>:<quantity><=<bound>'" in run.stderr


def test_tune_prints_the_calibration_progress_before_the_first_iteration(start_tuning_graph):
    # A fresh calibration directory (the kit's): the 12 samples are run, in pieces of 4
    # designs (one worker, pieces_per_worker = 3, config/graph.yaml).
    start_tuning_graph(parameters={'coordinator': {'calibration_samples': 12,
                                                   'final_telemetry': False}})
    tune = Path(sys.prefix) / 'bin' / 'tune'
    run = subprocess.run([str(tune), '--scenario', 'ride', '--n-vars', '2',
                          '--gradient', 'simplified', '--max-iterations', '1'],
                         capture_output=True, text=True, timeout=300, env=os.environ.copy())
    lines = run.stdout.splitlines()
    calibration = [line for line in lines if line.startswith('calibration (eq. 25):')]
    assert [line.split()[3] for line in calibration] == ['4/12', '8/12', '12/12'], \
        run.stdout + run.stderr
    first_iteration = next(i for i, line in enumerate(lines) if line.startswith('iteration'))
    assert lines.index(calibration[-1]) < first_iteration
    assert 'calibration full-model runs: 12' in run.stdout


def test_tune_and_inspect_bag_show_physical_metrics_the_recorded_telemetry_confirms(
        start_tuning_graph):
    """tune (started in physical units by name) prints the seat W_b RMS and the tyre
    lift-off time of the baseline and the reported design; inspect_bag --json has the
    same numbers; the reported design's telemetry in the bag gives them again."""
    import json

    import numpy as np
    import pytest

    from suspension_tuning.bag.reader import decode, read_messages
    from suspension_tuning.vehicle.params import load_scenarios_config

    # Every 4th history sample published (62.5 Hz): half the default's telemetry to record
    graph = start_tuning_graph(record=True, parameters={
        'full_vehicle_sim': {'telemetry_decimation': 4}})
    bin_dir = Path(sys.prefix) / 'bin'
    run = subprocess.run([str(bin_dir / 'tune'), '--scenario', 'ride', '--n-vars', '2',
                          '--gradient', 'full', '--max-iterations', '1', '--start',
                          'dpsf=1.2', 'gas_volume_l=0.35'],
                         capture_output=True, text=True, timeout=300, env=os.environ.copy())
    out = run.stdout
    assert 'physical metrics:' in out, out + run.stderr
    assert 'baseline design (config/design_space.yaml): f =' in out
    shown = {}  # label -> (baseline, reported) as tune prints them (3 decimals)
    for line in out[out.index('physical metrics:'):].splitlines()[2:]:
        label, values = line.rsplit(')', 1)
        shown[label.strip() + ')'] = tuple(float(v) for v in values.split())
    bag = graph.recorded_bag().path
    listing = subprocess.run([str(bin_dir / 'inspect_bag'), str(bag), '--json'],
                             capture_output=True, text=True, timeout=120)
    metrics = json.loads(listing.stdout)['optimum']['physical_metrics']
    reported, baseline = metrics['reported'], metrics['baseline']
    for name, label in (('a_rms_driver_mps2', 'seat W_b RMS, driver (m/s^2)'),
                        ('a_rms_passenger_mps2', 'seat W_b RMS, passenger (m/s^2)'),
                        ('tyre_lift_off_pct_rr', 'lift-off time RR (%)')):
        assert shown[label] == (pytest.approx(baseline[name], abs=5e-4),
                                pytest.approx(reported[name], abs=5e-4))
    # The telemetry of the reported design (its final run): W_b weighted seat accelerations
    # (weighted at the history rate, 250 Hz; every 4th sample published) after the ride's
    # settling time.  The metric is weighted at the integration rate (500 Hz): the two
    # differ by 0.1-0.3 % (measured: 3 designs at 250 Hz, one at 62.5 Hz).
    contents = read_messages(bag)
    settle = float(load_scenarios_config()['ride']['settle_s'])

    def samples(topic):
        messages = [decode(contents, m) for m in contents.on(topic)]
        t = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in messages])
        return t, messages

    for seat in ('driver', 'passenger'):
        t, messages = samples(f'/full_vehicle_sim/telemetry/seat/{seat}_wb')
        wb = np.array([m.accel.linear.z for m in messages])[t >= settle]
        rms = float(np.sqrt(np.mean(wb ** 2)))
        assert rms == pytest.approx(reported[f'a_rms_{seat}_mps2'], rel=0.01)
    t, messages = samples('/full_vehicle_sim/telemetry/tyres')
    fz = np.array([m.effort for m in messages])[t >= settle]  # FL, FR, RL, RR in N
    for i, tyre in enumerate(('fl', 'fr', 'rl', 'rr')):
        # every 8th sample of the 500 Hz count (measured: within 0.12 percentage points)
        assert 100.0 * np.mean(fz[:, i] <= 1e-3) == pytest.approx(
            reported[f'tyre_lift_off_pct_{tyre}'], abs=1.0)


def test_tune_without_a_coordinator_says_it_waits_then_what_to_check(ros_context):
    tune = Path(sys.prefix) / 'bin' / 'tune'
    domain = os.environ['ROS_DOMAIN_ID']
    run = subprocess.run([str(tune), '--server-timeout', '1', '--action', '/nobody/optimise'],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    waiting, error = run.stderr.strip().splitlines()
    # the wait is announced first, naming the action and the domain
    assert waiting.startswith('waiting for the action server /nobody/optimise on ROS '
                              f'domain {domain} (up to 1 s')
    assert error.startswith(f'error: no action server /nobody/optimise within 1 s on ROS '
                            f'domain {domain}: is the graph running')
    assert 'ROS_DOMAIN_ID' in error


@pytest.mark.parametrize(('option', 'value', 'reason'), [
    # the paper's 2 and 4 (eqs. 5, 7) and the ride8 preset of config/design_space.yaml
    ('--n-vars', '-2', "must be one of 2, 4, 8 (the paper's sizes and the presets of "
                       'config/design_space.yaml), got -2'),
    ('--max-iterations', '-1', 'must be at least 0 and at most 4294967295, got -1'),
    # the goal's max_iterations is a uint32
    ('--max-iterations', str(2**32), f'must be at least 0 and at most {2**32 - 1}, '
                                     f'got {2**32}'),
    ('--move-limit', '-0.2', 'must be at least 0, got -0.2'),
    ('--move-limit', 'nan', 'must be at least 0, got nan'),
    ('--server-timeout', '0', 'must be greater than 0, got 0'),
])
def test_tune_refuses_bad_numbers_naming_its_own_option(option, value, reason):
    tune = Path(sys.prefix) / 'bin' / 'tune'
    run = subprocess.run([str(tune), option, value], capture_output=True, text=True,
                         timeout=60)
    assert run.returncode == 2
    assert run.stderr.splitlines()[0].startswith('usage: tune')
    assert run.stderr.splitlines()[-1] == f'tune: error: argument {option}: {reason}'
    assert 'Traceback' not in run.stderr and 'rho0' not in run.stderr


def _serve_and_tune(ros_context, executor, action: str, execute, **server_options):
    """(node, server, tune process): a test Optimise server at ``action`` on ``node``
    spun by ``executor``, and ``tune --action action`` started against it."""
    from rclpy.action import ActionServer
    from rclpy.node import Node
    from suspension_tuning_interfaces.action import Optimise

    node = Node(action.strip('/').split('/')[0] + '_coordinator', context=ros_context)
    server = ActionServer(node, Optimise, action, execute, **server_options)
    executor.add(node)
    process = subprocess.Popen([str(Path(sys.prefix) / 'bin' / 'tune'), '--action', action],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    return node, server, process


def test_tune_says_so_when_the_coordinator_goes_away_before_the_result(ros_context, executor):
    """A server that vanishes mid-goal: an error on stderr and exit status 1, no hang."""
    import threading

    from suspension_tuning_interfaces.action import Optimise

    started, release = threading.Event(), threading.Event()

    def execute(goal_handle):
        started.set()
        release.wait(60.0)  # holds the goal until the server is gone
        goal_handle.abort()
        return Optimise.Result()

    node, server, process = _serve_and_tune(ros_context, executor, '/vanishing/optimise',
                                            execute)
    try:
        assert started.wait(60.0), 'the goal never arrived'
        # The action server leaves the graph mid-goal (not destroyed under a spin).
        executor.remove(node)
        server.destroy()
        _, stderr = process.communicate(timeout=60)
    finally:
        release.set()
        if process.poll() is None:
            process.kill()
    assert process.returncode == 1
    assert 'the action server /vanishing/optimise went away before the result' in stderr


def test_ctrl_c_cancels_the_running_goal_and_exits_130(ros_context, executor):
    """Ctrl-C while the goal runs: a cancel request reaches the server, and ``tune``
    exits with 130 (128 + SIGINT, the shell's convention) and no traceback."""
    import signal
    import threading
    import time

    from rclpy.action import CancelResponse
    from rclpy.callback_groups import ReentrantCallbackGroup
    from suspension_tuning_interfaces.action import Optimise

    started, cancelled = threading.Event(), threading.Event()

    def execute(goal_handle):
        started.set()
        deadline = time.monotonic() + 60.0
        while not goal_handle.is_cancel_requested and time.monotonic() < deadline:
            time.sleep(0.02)
        if goal_handle.is_cancel_requested:
            cancelled.set()
            goal_handle.canceled()
        else:
            goal_handle.abort()
        return Optimise.Result(message='cancelled')

    node, server, process = _serve_and_tune(ros_context, executor, '/held/optimise', execute,
                                            cancel_callback=lambda _: CancelResponse.ACCEPT,
                                            callback_group=ReentrantCallbackGroup())
    try:
        assert started.wait(60.0), 'the goal never arrived'
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
    executor.remove(node)
    server.destroy()
    assert cancelled.wait(10.0), 'no cancel request reached the server: ' + stderr
    assert process.returncode == 130, stderr
    assert 'cancelling' in stderr and 'Traceback' not in stderr


def test_ctrl_c_on_the_graph_mid_goal_stops_it_without_a_traceback(ros_context):
    """``graph`` interrupted while a goal runs: the goal's calls and status fail as ROS
    shuts down; the process must still stop at once and quietly, and ``tune`` says the
    server went away."""
    import signal
    import threading

    bindir = Path(sys.prefix) / 'bin'
    graph = subprocess.Popen([str(bindir / 'graph'), '--no-record'], stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True)
    graph_err: list[str] = []  # drained as it comes: a full pipe would block the graph
    drain = threading.Thread(target=lambda: graph_err.extend(graph.stderr), daemon=True)
    drain.start()
    tune = subprocess.Popen([str(bindir / 'tune'), '--scenario', 'handling', '--n-vars', '4',
                             '--gradient', 'full', '--max-iterations', '30',
                             '--server-timeout', '120'],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # Full-model gradients, 2n + 1 = 9 full runs per iteration: the goal still runs
        # for several iterations after the first feedback line.
        out = []
        for line in tune.stdout:  # ends when tune exits
            out.append(line)
            if 'iteration' in line:
                break
        assert out and 'iteration' in out[-1], (
            'no progress from tune: ' + ''.join(out) + tune.stderr.read() + ''.join(graph_err))
        graph.send_signal(signal.SIGINT)
        graph.wait(timeout=30)
        drain.join(timeout=10)
        tune_out, tune_err = tune.communicate(timeout=60)
    finally:
        for process in (graph, tune):
            if process.poll() is None:
                process.kill()
    graph_text = ''.join(graph_err)
    assert 'Traceback' not in graph_text, graph_text
    assert graph.returncode == 0, graph_text
    assert 'optimum in physical units' not in tune_out  # interrupted, not finished
    assert tune.returncode == 1 and 'went away before the result' in tune_err, tune_err


def test_a_server_that_never_answers_the_goal_is_an_error_not_a_hang(ros_context):
    """A server seen on the graph but not served (here: its node never spun; in the
    wild, a stale process) leaves the goal unanswered: tune says so and exits 1."""
    from rclpy.action import ActionServer
    from rclpy.node import Node
    from suspension_tuning_interfaces.action import Optimise

    node = Node('silent_coordinator', context=ros_context)
    server = ActionServer(node, Optimise, '/silent/optimise', lambda handle: Optimise.Result())
    # The timeout covers the server's discovery too: 8 s, since discovery of an action
    # server (its three services and two topics) took over 3 s on a loaded CI machine.
    try:
        run = subprocess.run([str(Path(sys.prefix) / 'bin' / 'tune'), '--action',
                              '/silent/optimise', '--server-timeout', '8'],
                             capture_output=True, text=True, timeout=120)
    finally:
        server.destroy()
        node.destroy_node()
    assert run.returncode == 1, run.stderr
    assert 'the goal was not answered within 8.0 s' in run.stderr
    assert 'Traceback' not in run.stderr


def _two_servers(ros_context, executor, action: str):
    """Two (node, Optimise server) pairs of ``action``, spun by ``executor``: each goal
    is held until it is cancelled (60 s at most), and its end listed ('cancelled' or
    'aborted')."""
    import time

    from rclpy.action import ActionServer, CancelResponse
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.node import Node
    from suspension_tuning_interfaces.action import Optimise

    ended = []

    def execute(goal_handle):
        deadline = time.monotonic() + 60.0
        while not goal_handle.is_cancel_requested and time.monotonic() < deadline:
            time.sleep(0.02)
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
            ended.append('cancelled')
        else:
            goal_handle.abort()
            ended.append('aborted')
        return Optimise.Result(message='held')

    servers = []
    for k in range(2):
        node = Node(f'twin_coordinator_{k}', context=ros_context)
        server = ActionServer(node, Optimise, action, execute,
                              cancel_callback=lambda _: CancelResponse.ACCEPT,
                              callback_group=ReentrantCallbackGroup())
        servers.append((node, server))
        executor.add(node)
    return servers, ended


def test_tune_refuses_an_action_two_servers_serve_before_sending_the_goal(
        ros_context, executor, ros_domain_id):
    servers, ended = _two_servers(ros_context, executor, '/twice/optimise')
    try:
        run = subprocess.run([str(Path(sys.prefix) / 'bin' / 'tune'), '--action',
                              '/twice/optimise'], capture_output=True, text=True, timeout=120)
    finally:
        for node, server in servers:
            executor.remove(node)  # no spin holds the server when it is destroyed
            server.destroy()
    assert run.returncode == 2, run.stderr
    assert (f'error: 2 action servers /twice/optimise on ROS domain {ros_domain_id} '
            '(ROS_DOMAIN_ID)') in run.stderr, run.stderr
    assert 'Traceback' not in run.stderr and not ended


def test_a_goal_two_servers_accept_is_reported_and_cancelled_not_a_crash(
        ros_context, executor, ros_domain_id):
    """Without the check before sending (a server discovered too late for it), both
    servers accept the goal; rclpy's 'Two goals were accepted with the same ID' becomes
    the same message, and the cancel request reaches both."""
    import time

    servers, ended = _two_servers(ros_context, executor, '/twice_late/optimise')
    try:
        run = subprocess.run([str(Path(sys.prefix) / 'bin' / 'tune'), '--action',
                              '/twice_late/optimise'], capture_output=True, text=True,
                             timeout=120,
                             env={**os.environ, 'SUSPENSION_TUNING_DISCOVERY_WINDOW_S': '0'})
        deadline = time.monotonic() + 10.0  # a cancelled goal ends within 0.02 s
        while len(ended) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        for node, server in servers:
            executor.remove(node)  # no spin holds the server when it is destroyed
            server.destroy()
    assert run.returncode == 2, run.stdout + run.stderr
    # rclpy either raises for the second acceptance or logs it: the count says 2 either way
    assert (f'error: 2 action servers /twice_late/optimise on ROS domain {ros_domain_id}'
            in run.stderr), run.stderr
    assert 'the goal was cancelled' in run.stderr
    assert 'Traceback' not in run.stderr, run.stderr
    assert ended == ['cancelled', 'cancelled']  # both servers ran it, both cancelled it


def test_rclpys_error_for_a_goal_accepted_twice_is_caught_and_spinning_goes_on():
    """rclpy raises 'Two goals were accepted with the same ID' from the executor when
    two acceptances of one goal are taken before its request is forgotten."""
    import threading

    from suspension_tuning.tune import spin

    class Executor:  # raises as rclpy's does once, then returns as after shutdown
        def __init__(self, error):
            self.context, self.error, self.spins = self, error, 0

        def ok(self):
            return True

        def spin(self):
            self.spins += 1
            if self.spins == 1:
                raise self.error

    duplicate = threading.Event()
    executor = Executor(RuntimeError('Two goals were accepted with the same ID (<handle>)'))
    spin(executor, duplicate)
    assert duplicate.is_set() and executor.spins == 2
    other = Executor(RuntimeError('failed to initialize wait set'))
    with pytest.raises(RuntimeError, match='wait set'):
        spin(other, threading.Event())


def test_tune_refuses_a_bad_condition_set_naming_file_condition_and_key(tmp_path, capsys):
    from suspension_tuning.tune import main

    path = tmp_path / 'conditions.yaml'
    path.write_text('conditions:\n  - name: autobahn\n    speed_kmh: 200.0\n')
    assert main(['--conditions', str(path)]) == 2
    assert capsys.readouterr().err.strip() == (
        f"error: {path}: condition 'autobahn': speed_kmh: 200 km/h is above the vehicle's "
        'top speed 132 km/h (config/vehicle.yaml longitudinal.top_speed_kmh)')


def test_tune_refuses_a_handling_constraint_with_a_condition_set(capsys):
    from suspension_tuning.paths import config_dir
    from suspension_tuning.tune import main

    # the shipped set's conditions are ride conditions: a ride quantity may be bounded
    # in every one of them, a handling one has no condition to hold in
    assert main(['--conditions', str(config_dir() / 'conditions.yaml'),
                 '--constraint', 'handling:f_hand<=0.8']) == 2
    err = capsys.readouterr().err
    assert '--constraint handling:f_hand<=0.8: with --conditions a constraint bounds a ride' \
        ' quantity, which then holds in every condition' in err
