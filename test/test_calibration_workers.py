"""The eq. 25 calibration batch is spread over every simulation worker.

With the paper's full model (minutes per run) the 30 calibration samples are where
several workers pay; the gradient evaluator splits them as the coordinator splits its
own batches.  A design gives the same bits alone or in a batch
(test_full_model.py), so two workers give the scaling one worker gives.
"""

import numpy as np
import pytest
from rclpy.parameter import Parameter

from suspension_tuning.testing import wait_for_future as wait

pytestmark = pytest.mark.ros

SAMPLES = 6  # fewer than the paper's 30 to keep the test short; same code path


def test_calibration_samples_are_split_over_the_workers_with_the_same_scaling(
        ros_context, executor, tmp_path):
    from rclpy.node import Node
    from suspension_tuning_interfaces.srv import Calibrate

    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode
    from suspension_tuning.nodes.gradient_evaluator import GradientEvaluatorNode

    workers = [FullVehicleSimNode(name, context=ros_context) for name in ('sim_a', 'sim_b')]
    spread = GradientEvaluatorNode(context=ros_context, parameter_overrides=[
        Parameter('calibration_dir', value=str(tmp_path / 'two')),
        Parameter('sim_workers', value=['/sim_a', '/sim_b'])])
    client = Node('calibration_test_client', context=ros_context)
    executor.add(*workers, spread, client)
    calibrate = client.create_client(Calibrate, '/gradient_evaluator/calibrate')
    assert calibrate.wait_for_service(timeout_sec=10.0)
    answer = wait(calibrate.call_async(Calibrate.Request(scenario='ride', n_vars=2,
                                                         n_samples=SAMPLES)))
    assert answer.success, answer.error
    assert answer.n_full_runs == SAMPLES
    # Two workers, pieces_per_worker = 3 (config/graph.yaml): 6 pieces of one design
    # each, handed to whichever worker is free, so both take part.
    assert sum(w.runs for w in workers) == SAMPLES and min(w.runs for w in workers) >= 1

    from suspension_tuning import evaluation
    from suspension_tuning.optim.simplified_gradient import calibrate as calibrate_locally

    local = calibrate_locally('ride', 2, n_samples=SAMPLES,
                              run_full=lambda name, x: evaluation.evaluate(name, x).result)
    np.testing.assert_array_equal(answer.full_min, [f.f_a_min for f in local.functions])
    np.testing.assert_array_equal(answer.full_max, [f.f_a_max for f in local.functions])
    np.testing.assert_array_equal(answer.r_squared, [f.r2 for f in local.functions])
