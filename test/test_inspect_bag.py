"""inspect_bag: the numbers it reports are the ones in the bag's messages, exactly."""

import json
from pathlib import Path

import numpy as np
import pytest

T0 = 1_700_000_000_000_000_000  # log time of the first message, ns

#: Four Dynamic-Q iterations of a 2-variable run; numbers chosen to be exact in binary
#: except the last f, which checks that no rounding happens on the way.
RECORDS = [
    dict(
        iteration=0,
        x=[0.5, 0.5],
        f=2.0,
        g=[0.25, -1.0],
        move_limit=0.25,
        move_limit_next=0.25,
        max_violation=0.25,
        n_full_runs=1,
        n_simplified_runs=4,
        wall_time_s=1.5,
    ),
    dict(
        iteration=1,
        x=[0.25, 0.75],
        f=1.5,
        g=[0.0625, -1.0],
        move_limit=0.25,
        move_limit_next=0.125,
        max_violation=0.0625,
        n_full_runs=2,
        n_simplified_runs=8,
        wall_time_s=3.0,
    ),
    dict(
        iteration=2,
        x=[0.125, 0.875],
        f=1.25,
        g=[-0.5, -1.0],
        move_limit=0.125,
        move_limit_next=0.0625,
        max_violation=0.0,
        n_full_runs=3,
        n_simplified_runs=12,
        wall_time_s=4.5,
    ),
    dict(
        iteration=3,
        x=[0.1, 0.9],
        f=1.2345678901234567,
        g=[-0.75, -1.0],
        move_limit=0.0625,
        move_limit_next=0.03125,
        max_violation=0.0,
        n_full_runs=4,
        n_simplified_runs=16,
        wall_time_s=6.0,
    ),
]
PHYSICAL = {'dpsf': 0.3997, 'gas_volume_l': 0.55}  # x -> physical, eqs. 4-6 (not checked here)
BASELINE = {'dpsf': 1.0, 'gas_volume_l': 0.3}  # config/design_space.yaml's baseline
#: Physical metrics of the reported design and the baseline (m/s^2 and %), binary-exact.
METRICS = {'a_rms_driver_mps2': 1.125, 'a_rms_passenger_mps2': 1.375,
           'tyre_lift_off_pct_fl': 2.5}
BASELINE_METRICS = {'a_rms_driver_mps2': 1.25, 'a_rms_passenger_mps2': 1.5,
                    'tyre_lift_off_pct_fl': 3.0}


def build_bag(path):
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Imu, JointState
    from std_msgs.msg import String
    from suspension_tuning_interfaces.action import Optimise
    from suspension_tuning_interfaces.msg import IterationRecord, ValveState
    from suspension_tuning_interfaces.srv import EvaluateDesign

    from suspension_tuning.bag.writer import BagWriter

    t = T0
    with BagWriter(path) as bag:

        def put(topic, type_name, msg):
            nonlocal t
            bag.add_topic(topic, type_name)
            bag.write(topic, serialize_message(msg), t)
            t += 1_000_000

        bag.add_metadata('run_config', {'yaml': 'scenario: ride\nn_vars: 2\n'})
        put(
            '/optimisation/run_config',
            'std_msgs/msg/String',
            String(data='scenario: ride\nn_vars: 2\n'),
        )
        for n_designs in (1, 3):  # two requests: 1 design, then 3 (2 variables each)
            event = EvaluateDesign.Event()
            event.info.event_type = 1  # REQUEST_RECEIVED
            event.request = [
                EvaluateDesign.Request(scenario='ride', n_vars=2, designs=[0.5] * (2 * n_designs))
            ]
            put(
                '/sim_0/evaluate/_service_event',
                'suspension_tuning_interfaces/srv/EvaluateDesign_Event',
                event,
            )
            event.info.event_type = 2  # RESPONSE_SENT: not counted as a request
            event.request = []
            put(
                '/sim_0/evaluate/_service_event',
                'suspension_tuning_interfaces/srv/EvaluateDesign_Event',
                event,
            )
        for rec in RECORDS:
            put(
                '/optimisation/progress',
                'suspension_tuning_interfaces/msg/IterationRecord',
                IterationRecord(**rec),
            )
        # valve: ride state until step 20 (0.100 s at 5 ms), handling commanded at step 20,
        # actual after 10 steps = 50 ms (paper section 3: 50-100 ms)
        for step in range(40):
            commanded = (1, 1, 1, 1) if step >= 20 else (0, 0, 0, 0)
            actual = (1, 1, 1, 1) if step >= 30 else (0, 0, 0, 0)
            for topic, state in (
                ('/suspension/valve_command', commanded),
                ('/suspension/valve_state', actual),
            ):
                msg = ValveState(step=step)
                msg.header.stamp.sec, msg.header.stamp.nanosec = 0, step * 5_000_000
                (msg.front_spring, msg.front_damping, msg.rear_spring, msg.rear_damping) = state
                put(topic, 'suspension_tuning_interfaces/msg/ValveState', msg)
        # telemetry of two runs; the simulated time restarts for the second (final) one
        for run in range(2):
            for k in range(50):
                seats = JointState(
                    name=['driver', 'passenger'], effort=[np.sin(k / 5.0) + run, np.cos(k / 5.0)]
                )
                seats.header.stamp.nanosec = k * 10_000_000
                put('/sim_0/telemetry/seats', 'sensor_msgs/msg/JointState', seats)
                imu = Imu()
                imu.header.stamp.nanosec = k * 10_000_000
                imu.linear_acceleration.z = 9.81
                put('/sim_0/telemetry/imu', 'sensor_msgs/msg/Imu', imu)
        result = Optimise.Result(
            success=True,
            message='converged',
            x=RECORDS[-1]['x'],
            f=RECORDS[-1]['f'],
            g=RECORDS[-1]['g'],
            feasible=True,  # the last record is the best feasible one: lowest f, g <= 0
            best_iteration=3,
            max_violation=0.0,
            physical_names=list(PHYSICAL),
            physical_values=list(PHYSICAL.values()),
            metric_names=list(METRICS),
            metrics=list(METRICS.values()),
            baseline_x=[0.3103448275862069, 0.4],
            baseline_f=2.5,
            baseline_physical_values=list(BASELINE.values()),
            baseline_metrics=list(BASELINE_METRICS.values()),
            iterations=3,
            n_full_runs=4,
            n_simplified_runs=16,
            n_calibration_runs=30,
            history=[IterationRecord(**r) for r in RECORDS],
            wall_time_s=6.5,
        )
        put('/optimisation/result', 'suspension_tuning_interfaces/action/Optimise_Result', result)
    return path


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    return build_bag(tmp_path_factory.mktemp('inspect') / 'run')


def test_summary_reports_topics_counts_and_duration(bag):
    from suspension_tuning.inspect_bag import summary

    info = summary(bag)
    assert info['complete']
    counts = {t: v['count'] for t, v in info['topics'].items()}
    # 1 run_config + 4 events + 4 progress + 2 x 40 valve + 2 x 2 x 50 telemetry + 1 result
    assert counts == {
        '/optimisation/run_config': 1,
        '/sim_0/evaluate/_service_event': 4,
        '/optimisation/progress': 4,
        '/suspension/valve_command': 40,
        '/suspension/valve_state': 40,
        '/sim_0/telemetry/seats': 100,
        '/sim_0/telemetry/imu': 100,
        '/optimisation/result': 1,
    }
    assert info['message_count'] == 290
    assert info['duration_s'] == pytest.approx(0.289)  # 289 gaps of 1 ms
    assert info['run_config'] == {'scenario': 'ride', 'n_vars': 2}


def test_iteration_table_and_optimum_equal_the_messages_exactly(bag):
    from suspension_tuning.inspect_bag import summary

    info = summary(bag)
    for got, want in zip(info['iterations'], RECORDS):
        assert got == want  # every field, floats compared exactly
    assert len(info['iterations']) == 4
    best = info['optimum']
    assert best['x'] == RECORDS[-1]['x'] and best['f'] == RECORDS[-1]['f']
    assert best['g'] == RECORDS[-1]['g']
    assert best['physical'] == PHYSICAL
    assert best['baseline'] == {'x': [0.3103448275862069, 0.4], 'f': 2.5, 'physical': BASELINE}
    assert best['physical_metrics'] == {'reported': METRICS, 'baseline': BASELINE_METRICS}
    assert best['success'] and best['message'] == 'converged'
    assert best['feasible'] and best['best_iteration'] == 3 and best['source'] == 'result'
    ev = info['evaluations']
    assert (
        ev['iterations'],
        ev['n_full_runs'],
        ev['n_simplified_runs'],
        ev['n_calibration_runs'],
    ) == (3, 4, 16, 30)
    # 2 requests received, with 1 and 3 designs
    assert ev['services'] == {'/sim_0/evaluate': {'requests': 2, 'designs': 4}}


def _optimisation_bag(path, records, **result):
    """A bag of one run: run_config (gtol 1e-3), progress records and the result."""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String
    from suspension_tuning_interfaces.action import Optimise
    from suspension_tuning_interfaces.msg import IterationRecord

    from suspension_tuning.bag.writer import BagWriter

    config = 'scenario: ride\nn_vars: 2\noptimiser_options: {gtol: 0.001}\n'
    with BagWriter(path) as bag:
        bag.add_metadata('run_config', {'yaml': config})
        bag.add_topic('/optimisation/run_config', 'std_msgs/msg/String')
        bag.write('/optimisation/run_config', serialize_message(String(data=config)), T0)
        bag.add_topic('/optimisation/progress', 'suspension_tuning_interfaces/msg/IterationRecord')
        for k, rec in enumerate(records):
            bag.write('/optimisation/progress', serialize_message(IterationRecord(**rec)),
                      T0 + 1 + k)
        bag.add_topic('/optimisation/result',
                      'suspension_tuning_interfaces/action/Optimise_Result')
        message = Optimise.Result(history=[IterationRecord(**r) for r in records], **result)
        bag.write('/optimisation/result', serialize_message(message), T0 + 1 + len(records))
    return path


#: A run whose last iterate (3) has the lowest f but violates a constraint; iteration
#: 2 is the best feasible one.
INFEASIBLE_LAST = [*RECORDS[:3], dict(RECORDS[3], f=1.0, g=[0.0625, -1.0],
                                      max_violation=0.0625)]


def test_inspect_shows_the_reported_design_and_its_iteration_not_the_last(tmp_path, capsys):
    from suspension_tuning.inspect_bag import main, summary, write_plots

    best = INFEASIBLE_LAST[2]
    bag = _optimisation_bag(
        tmp_path / 'run', INFEASIBLE_LAST, success=False, x=best['x'], f=best['f'],
        g=best['g'], feasible=True, best_iteration=2, max_violation=0.0, iterations=3,
        message='best feasible design: iteration 2; Dynamic-Q stopped: maximum number of '
        'iterations reached (final point infeasible)', physical_names=list(PHYSICAL),
        physical_values=list(PHYSICAL.values()))
    info = summary(bag)
    optimum = info['optimum']
    assert (optimum['x'], optimum['f'], optimum['best_iteration']) == (best['x'], 1.25, 2)
    assert optimum['feasible'] and optimum['source'] == 'result'
    assert optimum['last_iterate']['iteration'] == 3 and optimum['last_iterate']['f'] == 1.0
    assert main([str(bag)]) == 0
    text = capsys.readouterr().out
    assert 'best feasible design: iteration 2 (max violation 0)' in text
    assert 'f = 1.25' in text and 'last iterate: iteration 3, f = 1.0' in text
    assert main([str(bag), '--json']) == 0
    assert json.loads(capsys.readouterr().out)['optimum']['best_iteration'] == 2
    # the reported design is marked on both; no telemetry in this bag
    assert {p.name for p in write_plots(bag, tmp_path / 'plots')} == {
        'convergence.png', 'design.png'}


def test_inspect_says_plainly_when_no_design_was_feasible(tmp_path, capsys):
    from suspension_tuning.inspect_bag import main

    # every record violates a constraint: iteration 1 the least (0.0625, as in RECORDS),
    # the others by 0.5
    records = [dict(r, max_violation=0.5) for r in RECORDS]
    records[1] = RECORDS[1]
    bag = _optimisation_bag(
        tmp_path / 'run', records, x=RECORDS[1]['x'], f=RECORDS[1]['f'], g=RECORDS[1]['g'],
        feasible=False, best_iteration=1, max_violation=0.0625, iterations=3,
        message='no feasible design found: ...', physical_names=list(PHYSICAL),
        physical_values=list(PHYSICAL.values()))
    assert main([str(bag)]) == 0
    text = capsys.readouterr().out
    assert 'reported design (FAILED' in text and 'optimum' not in text
    assert ('no feasible design found: the reported design is the least violating one '
            '(max g = 0.0625), iteration 1') in text


#: An old bag: the run_config, progress and result messages of a 4-variable ride run
#: of make demo (bags/sample), recorded before results named their best design.  Its
#: last iterate (30, max violation 0.0444) is infeasible; iteration 29 has the lowest
#: f (0.11316) among those within gtol = 1e-3 (its max violation 7.4e-4).
OLD_RESULT = Path(__file__).parent / 'fixtures' / 'old_result_ride'


def test_an_old_bag_reports_the_best_feasible_design_found_in_its_history(tmp_path, capsys):
    from suspension_tuning.bag.reader import decode, read_messages
    from suspension_tuning.inspect_bag import main, summary
    from suspension_tuning.tuning import physical_settings

    contents = read_messages(OLD_RESULT)
    old = decode(contents, contents.on('/optimisation/result')[-1])
    assert not hasattr(old, 'best_iteration')  # the old layout: x is the last iterate
    info = summary(OLD_RESULT)
    records, optimum = info['iterations'], info['optimum']
    assert optimum['source'] == 'history' and optimum['gtol'] == 1e-3
    assert optimum['feasible'] and optimum['best_iteration'] == 29
    assert optimum['x'] == records[29]['x'] and optimum['f'] == records[29]['f']
    assert optimum['f'] == pytest.approx(0.11315855, abs=1e-8)  # inspect_bag's table
    assert optimum['physical'] == physical_settings(records[29]['x'])
    assert list(old.x) == records[30]['x']  # what the old result called the optimum
    assert optimum['last_iterate']['iteration'] == 30
    assert main([str(OLD_RESULT), '--plots', str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert 'best feasible design: iteration 29' in text
    assert 'found in the recorded history with gtol = 0.001' in text
    assert 'last iterate: iteration 30' in text


def test_valve_switching_event_and_its_delay(bag):
    from suspension_tuning.inspect_bag import summary

    events = summary(bag)['valve_events']
    assert len(events) == 1
    event = events[0]
    assert event['step'] == 20 and event['state'] == [1, 1, 1, 1]
    assert event['time_s'] == pytest.approx(0.100)  # step 20 x 5 ms
    assert event['delay_s'] == pytest.approx(0.050)  # 10 steps x 5 ms


def test_cli_prints_table_json_and_writes_plots(bag, tmp_path, capsys):
    from suspension_tuning.inspect_bag import main

    assert main([str(bag), '--plots', str(tmp_path / 'plots')]) == 0
    text = capsys.readouterr().out
    assert '/optimisation/progress' in text and 'converged' in text
    assert 'f = 1.2345678901234567' in text
    assert 'delay 50.0 ms' in text
    assert 'baseline design: f = 2.5' in text
    seat = next(line for line in text.splitlines() if 'seat W_b RMS, driver (m/s^2)' in line)
    assert seat.split()[-2:] == ['1.250', '1.125']  # baseline, then the optimum
    for name in ('convergence.png', 'design.png', 'metrics.png', 'telemetry.png'):
        data = (tmp_path / 'plots' / name).read_bytes()
        assert data[:8] == b'\x89PNG\r\n\x1a\n' and len(data) > 5000
    assert main([str(bag), '--json']) == 0
    info = json.loads(capsys.readouterr().out)
    assert info['optimum']['f'] == RECORDS[-1]['f']
    assert info['optimum']['physical_metrics']['reported'] == METRICS
    assert main([str(tmp_path / 'missing')]) == 2


def test_last_iteration_resumes_dynamic_q_at_the_last_record(bag):
    from suspension_tuning.inspect_bag import last_iteration
    from suspension_tuning.optim.dynamic_q import DynamicQ

    state = last_iteration(bag)
    assert state['iteration'] == 3 and state['scenario'] == 'ride' and state['n_vars'] == 2
    assert list(state['x']) == RECORDS[-1]['x']
    assert [h['f'] for h in state['history']] == [r['f'] for r in RECORDS]
    # move limit after record k = its move_limit_next (the optimiser's rho_next)
    assert [h['rho_next'] for h in state['history']] == [0.25, 0.125, 0.0625, 0.03125]
    optimiser = DynamicQ(
        state['history'][0]['x'], [0.001, 0.001], [1.0, 1.0], history=state['history']
    )
    kind, x = optimiser.ask()
    # the last record has no gradient yet: Dynamic-Q continues with the gradient there
    assert kind == 'gradient'
    assert list(x) == RECORDS[-1]['x']
    assert len(optimiser.history) == 4


def test_last_iteration_without_records_raises(tmp_path):
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    from suspension_tuning.bag.writer import BagWriter
    from suspension_tuning.inspect_bag import last_iteration

    with BagWriter(tmp_path / 'empty') as writer:
        writer.add_topic('/chatter', 'std_msgs/msg/String')
        writer.write('/chatter', serialize_message(String(data='hi')), T0)
    with pytest.raises(ValueError, match='no iteration records'):
        last_iteration(tmp_path / 'empty')


def test_reindex_option_repairs_a_truncated_bag_before_reporting(bag, tmp_path, capsys):
    import shutil

    from suspension_tuning.inspect_bag import main

    copy = tmp_path / 'copy'
    shutil.copytree(bag, copy)
    (copy / 'metadata.yaml').unlink()
    mcap = copy / 'run_0.mcap'
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) - 200])  # cut inside the summary section
    assert main([str(copy), '--json', '--reindex']) == 0
    info = json.loads(capsys.readouterr().out)
    # the summary was lost, every chunk was whole: all 290 messages, complete again
    assert info['complete'] and info['message_count'] == 290
    assert (copy / 'metadata.yaml').is_file()


def test_inspect_of_an_unreadable_file_says_why(tmp_path, capsys):
    from suspension_tuning.inspect_bag import main

    garbage = tmp_path / 'garbage.mcap'
    garbage.write_bytes(b'this is not a bag')
    assert main([str(garbage)]) == 2
    assert 'not an MCAP file' in capsys.readouterr().err


def test_a_resumed_run_prints_its_best_feasible_design_not_its_last_iterate():
    from scipy.optimize import OptimizeResult

    from suspension_tuning.inspect_bag import format_resumed

    # last iterate x = (0.1, 0.9) infeasible; iteration 2 of the whole run is the best
    result = OptimizeResult(
        message='stopped: maximum number of iterations reached (final point infeasible)',
        nit=5, n_full_runs=6, n_simplified_runs=40, x=[0.1, 0.9], f=1.0,
        x_best=[0.25, 0.75], f_best=1.5, g_best=[-0.5], best_iteration=2,
        best_feasible=True, max_violation_best=0.0)
    line = format_resumed(result)
    assert 'best feasible design: iteration 2: f = 1.5, x = [0.25, 0.75]' in line
    assert 'iterations 5, full-model runs 6, simplified runs 40' in line
