"""The demo: its exit status (an optimiser's own stop is a result, anything else a failure)
and its report of the reported design."""

from suspension_tuning.demo import optimiser_stopped


def test_demo_reports_an_optimiser_stop_and_fails_on_anything_else():
    # Dynamic-Q's stops (optim/dynamic_q.py STATUS_MESSAGES 0-4), with the suffix the
    # result adds at an infeasible final point
    assert optimiser_stopped('converged: step shorter than xtol')
    assert optimiser_stopped(
        'stopped: maximum number of iterations reached (last iterate infeasible)'
    )
    assert optimiser_stopped('stopped: move limit below rho_min at an infeasible point')
    assert optimiser_stopped('converged: a corner of the box where the gradient points out '
                             'of it, no constraint active (first-order optimal)')  # 6
    # stopped from outside, or no optimisation at all: the demo failed
    assert not optimiser_stopped('stopped by the callback or the caller')
    assert not optimiser_stopped('bad goal: n_vars must be 2 or 4')
    assert not optimiser_stopped('stopped: ROS shut down under the goal')


def test_demo_reads_the_optimiser_stop_after_the_sentence_on_the_reported_design():
    # the coordinator's result message: the reported design, then Dynamic-Q's stop
    assert optimiser_stopped('best feasible design: iteration 29; Dynamic-Q stopped: '
                             'maximum number of iterations reached (last iterate infeasible)')
    assert optimiser_stopped('no feasible design found: the reported design is the least '
                             'violating one (max g = 0.0444), iteration 4; Dynamic-Q '
                             'stopped: move limit below rho_min at an infeasible point')
    assert not optimiser_stopped('best feasible design: iteration 3; Dynamic-Q cancelled')


def test_demo_report_says_when_no_design_was_feasible():
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.demo import report

    names = ['dpsf_front', 'gas_volume_front_l', 'dpsf_rear', 'gas_volume_rear_l']
    # an infeasible reported design: the tyre-hop constraint of FL 0.0444 above 0
    result = Optimise.Result(
        success=False, message='no feasible design found: the reported design is the least '
        'violating one (max g = 0.0444), iteration 4; Dynamic-Q stopped: maximum number of '
        'iterations reached (last iterate infeasible)', x=[0.5, 0.5, 0.5, 0.5], f=0.1,
        g=[0.0444, -0.1, -0.1, -0.1], feasible=False, best_iteration=4, max_violation=0.0444,
        physical_names=names, physical_values=[1.5, 0.35, 1.5, 0.35], iterations=30,
        baseline_x=[0.31, 0.4, 0.31, 0.4], baseline_f=0.2,  # baseline f 0.2: 50 % better
        baseline_physical_values=[1.0, 0.3, 1.0, 0.3])
    text = report('ride', result)
    assert 'ride: no feasible design found' in text
    assert 'least violating' in text.splitlines()[1] and 'optimum' not in text
    assert '(improvement 50.0 %)' in text
    result.feasible, result.message = True, 'best feasible design: iteration 4; Dynamic-Q ...'
    assert 'optimum' in report('ride', result).splitlines()[1]


def test_demo_report_shows_the_physical_metrics_of_the_baseline_and_the_optimum():
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.demo import report

    result = Optimise.Result(
        message='best feasible design: iteration 2', f=0.1, g=[-0.5] * 4, feasible=True,
        physical_names=['dpsf_front'], physical_values=[1.5], baseline_x=[0.31],
        baseline_f=0.2, baseline_physical_values=[1.0],
        metric_names=['a_rms_driver_mps2', 'tyre_lift_off_pct_rl'],
        metrics=[1.25, 0.5], baseline_metrics=[1.5, 2.0])
    lines = report('ride', result).splitlines()
    seat = next(line for line in lines if 'seat W_b RMS, driver (m/s^2)' in line)
    assert seat.split()[-2:] == ['1.500', '1.250']  # baseline, then the optimum
    lift = next(line for line in lines if 'lift-off time RL (%)' in line)
    assert lift.split()[-2:] == ['2.000', '0.500']


def test_demo_waits_for_the_bag_while_the_recorder_records_and_not_when_it_stalls():
    import threading
    import time
    from types import SimpleNamespace

    import pytest

    from suspension_tuning.demo import wait_for_bag

    recorder = SimpleNamespace(received=0, session=SimpleNamespace(closed_bags=[]))

    def drain() -> None:  # a recorder still recording 3 stall periods after the result
        for _ in range(12):
            time.sleep(0.05)
            recorder.received += 1
        recorder.session.closed_bags.append('bag')

    worker = threading.Thread(target=drain)
    worker.start()
    wait_for_bag(recorder, 0, stall_s=0.2)  # 0.6 s in all: waits, since it records
    worker.join()
    assert recorder.session.closed_bags == ['bag']
    with pytest.raises(TimeoutError, match='nothing recorded for 0.2 s'):
        wait_for_bag(recorder, 1, stall_s=0.2)  # nothing recorded, no bag closed
