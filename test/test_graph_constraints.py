"""Optimise goals with extra constraints from other scenarios, through the graph.

A goal asks to minimise f_hand subject to f_ride <= bound (the ride scenario's
objective, gradient from its scaled simplified model) or to a ride metric (full-model
central differences): at the optimum the extra constraint holds within the
optimiser's tolerance, the result says which gradient each constraint used, and a bad
specification is answered with an error while the coordinator keeps serving.
"""

import numpy as np
import pytest
from rclpy.parameter import Parameter

pytestmark = pytest.mark.ros

SAMPLES = 8  # eq. 25 samples per scenario: fewer than the paper's 30, same code path
GTOL = 1e-3  # config/optimiser.yaml vehicle gtol: feasible when g <= 1e-3
# On the sett paving f_ride of the handling optimum (dpsf 3, 0.1 L) is about 0.36 and
# that of the ride optimum about 0.11 (docs/pareto.md), so a bound of 0.2 is active.
# (The handling objective is taken here: its eq. 11 constraints are inactive, whereas
# the ride run's tyre-hop constraints, active and piecewise constant on the paving,
# can leave a short run infeasible.)
F_RIDE_BOUND = 0.2


@pytest.fixture
def graph(ros_context, tmp_path):
    from rclpy.node import Node

    from suspension_tuning.graph import SpinningGraph, build_nodes

    # The recorder keeps the run's three topics only (an action status latched on the
    # domain by another test would enter through the pre-run window otherwise).
    topics = ['/optimisation/run_config', '/optimisation/progress', '/optimisation/result']
    nodes = build_nodes(workers=1, record=True, context=ros_context, overrides={
        'gradient_evaluator': [Parameter('calibration_dir', value=str(tmp_path))],
        'coordinator': [Parameter('calibration_samples', value=SAMPLES),
                        Parameter('final_telemetry', value=False)],
        'recorder': [Parameter('output_dir', value=str(tmp_path / 'bags')),
                     Parameter('topics', value=topics), Parameter('post_run_s', value=0.2)]})
    client_node = Node('constraints_client', context=ros_context)
    spinning = SpinningGraph(nodes, [client_node])
    try:
        yield nodes, client_node
    finally:
        spinning.shutdown()


def _run(client_node, goal):
    from rclpy.action import ActionClient
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning.nodes._spin import wait_future

    client = ActionClient(client_node, Optimise, '/coordinator/optimise')
    assert client.wait_for_server(timeout_sec=10.0)
    handle = wait_future(client.send_goal_async(goal), 30.0)
    return wait_future(handle.get_result_async(), 300.0).result


def _goal(*constraints, **fields):
    from suspension_tuning_interfaces.action import Optimise
    from suspension_tuning_interfaces.msg import Constraint

    fields = {'scenario': 'handling', 'n_vars': 2, 'gradient_source': 'simplified',
              'max_iterations': 15, **fields}
    return Optimise.Goal(constraints=[Constraint(scenario=s, quantity=q, upper_bound=b)
                                      for s, q, b in constraints], **fields)


def test_a_constrained_goal_respects_its_extra_constraint_at_the_optimum(graph):
    import time

    import yaml

    from suspension_tuning import evaluation
    from suspension_tuning.bag.reader import decode, read_messages
    from suspension_tuning.nodes.recorder import RecorderNode

    nodes, client_node = graph
    result = _run(client_node, _goal(('ride', 'f_ride', F_RIDE_BOUND)))
    assert result.success, result.message
    assert list(result.constraint_gradient_sources) == ['simplified']
    # The ride scenario's full model at the optimum, in-process: within gtol of the
    # bound, and the value the result reports.
    f_ride = evaluation.evaluate('ride', np.asarray(result.x)[None, :]).f[0]
    assert f_ride <= F_RIDE_BOUND + GTOL
    assert result.constraint_values[0] == pytest.approx(f_ride, abs=1e-12)
    assert result.g[-1] == pytest.approx(f_ride - F_RIDE_BOUND, abs=1e-12)
    assert len(result.g) == 5  # 4 eq. 11 constraints, then the extra one
    # Both scenarios calibrated (eq. 25): SAMPLES full runs each.
    assert result.n_calibration_runs == 2 * SAMPLES
    # Recorded like any run: the constraints in the bag's run configuration and result.
    recorder = next(n for n in nodes if isinstance(n, RecorderNode))
    deadline = time.monotonic() + 30.0
    while not recorder.session.closed_bags and time.monotonic() < deadline:
        time.sleep(0.05)
    contents = read_messages(recorder.session.closed_bags[0])
    config = yaml.safe_load(contents.metadata['run_config']['yaml'])
    assert config['constraints'] == [{'scenario': 'ride', 'quantity': 'f',
                                      'upper_bound': F_RIDE_BOUND}]
    assert config['constraint_gradient_sources'] == ['simplified']
    recorded = decode(contents, contents.on('/optimisation/result')[0])
    assert list(recorded.constraint_values) == list(result.constraint_values)


def test_bad_constraints_are_answered_with_errors_and_the_coordinator_keeps_serving(graph):
    from suspension_tuning import evaluation

    _, client_node = graph
    bad = [(('offroad', 'f', 0.8), "unknown scenario 'offroad'"),
           (('handling', 'roll_peak', 4.0), "unknown metric 'roll_peak'"),
           (('handling', 'f_hand', float('nan')), 'must be finite')]
    for spec, message in bad:
        result = _run(client_node, _goal(spec))
        assert not result.success
        assert message in result.message, result.message
    # Still serving: a metric constraint (driver seat W_b RMS <= 1.5 m/s^2 on the
    # paving; the handling optimum gives about 1.9), gradient from full-model differences.
    result = _run(client_node, _goal(('ride', 'a_rms_driver_mps2', 1.5), max_iterations=10))
    assert result.success, result.message
    assert list(result.constraint_gradient_sources) == ['full']
    ride = evaluation.evaluate('ride', np.asarray(result.x)[None, :])
    names = list(ride.metric_names)
    assert ride.metrics[0, names.index('a_rms_driver_mps2')] <= 1.5 + GTOL
