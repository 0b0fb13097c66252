"""An optimisation recorded by the recorder resumes from the bag's last iteration.

The graph runs 2 iterations of the 2-variable handling optimisation (full-model
gradients) with the recorder on; resuming the bag in-process up to 5 iterations must
reach exactly the iterates of an uninterrupted 5-iteration run (the model and the
optimiser are deterministic, and the bag carries each record's next move limit).
"""

import threading
import time

import numpy as np
import pytest
from rclpy.parameter import Parameter

pytestmark = pytest.mark.ros


def wait(future, timeout_s=300.0):
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    assert done.wait(timeout_s), 'no answer in time'
    return future.result()


def test_recorded_run_resumes_to_the_uninterrupted_iterates(ros_context, executor, tmp_path):
    from rclpy.action import ActionClient
    from rclpy.node import Node
    from suspension_tuning_interfaces.action import Optimise

    from suspension_tuning import evaluation
    from suspension_tuning.nodes.coordinator import CoordinatorNode
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode
    from suspension_tuning.nodes.recorder import RecorderNode
    from suspension_tuning.resume import resume
    from suspension_tuning.tuning import FullEvaluation, TuningRequest, optimise

    recorder = RecorderNode(context=ros_context, parameter_overrides=[
        Parameter('output_dir', value=str(tmp_path)), Parameter('post_run_s', value=0.5)])
    coordinator = CoordinatorNode(context=ros_context, parameter_overrides=[
        Parameter('final_telemetry', value=False)])
    client_node = Node('resume_test_client', context=ros_context)
    executor.add(FullVehicleSimNode(context=ros_context), coordinator, recorder, client_node)
    client = ActionClient(client_node, Optimise, '/coordinator/optimise')
    assert client.wait_for_server(timeout_sec=10.0)
    time.sleep(1.5)  # let the recorder discover the coordinator's latched topics
    handle = wait(client.send_goal_async(Optimise.Goal(
        scenario='handling', n_vars=2, gradient_source='full', max_iterations=2)))
    short = wait(handle.get_result_async()).result
    deadline = time.monotonic() + 30.0
    while not recorder.session.closed_bags:
        assert time.monotonic() < deadline, 'the recorder did not close the run bag'
        time.sleep(0.1)
    bag = recorder.session.closed_bags[-1]
    resumed = resume(bag, max_iterations=5)
    options = coordinator.options.as_dict() | {'maxiter': 5}

    def full_model(points):
        run = evaluation.evaluate('handling', points)
        return FullEvaluation(run.f, run.g)

    straight = optimise(TuningRequest('handling', 2, None, 'full', options), full_model)
    assert short.iterations == 2
    np.testing.assert_array_equal(resumed.x, straight.x)
    assert resumed.f == straight.f
    assert resumed.nit == straight.nit
    # The resumed run counts the recorded runs plus its own.  A record is published
    # after its evaluation and before the gradient at that point, so the resumed run's
    # first gradient (2n = 4 runs) is the one the interrupted run never took: the totals
    # equal the uninterrupted run's.
    assert resumed.n_full_runs == straight.n_full_runs
