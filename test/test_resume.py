"""An optimisation recorded by the recorder resumes from the bag's last iteration.

The graph runs 1 iteration of the 2-variable handling optimisation (full-model
gradients) with the recorder on; resuming the bag in-process up to 5 iterations must
reach exactly the iterates of an uninterrupted 5-iteration run (the model and the
optimiser are deterministic, and the bag carries each record's next move limit).
"""

import numpy as np
import pytest

pytestmark = pytest.mark.ros


def test_recorded_run_resumes_to_the_uninterrupted_iterates(start_tuning_graph):
    from suspension_tuning import evaluation
    from suspension_tuning.answer_check import check_options
    from suspension_tuning.resume import resume
    from suspension_tuning.tuning import (
        FullEvaluation,
        TuningRequest,
        optimise,
        with_noise_levels,
    )

    graph = start_tuning_graph(record=True, parameters={
        'recorder': {'post_run_s': 0.5}, 'coordinator': {'final_telemetry': False}})
    coordinator = graph.node('coordinator')
    # one iteration: the resumed run takes the step to the optimum's corner itself (the
    # bound-KKT test ends an uninterrupted run there, at iteration 2)
    short = graph.optimise('handling', 2, 'full', max_iterations=1)
    bag = graph.recorded_bag().path
    resumed = resume(bag, max_iterations=5)
    options = coordinator.options.as_dict() | {'maxiter': 5}

    def full_model(points):
        run = evaluation.evaluate('handling', points)
        return FullEvaluation(run.f, run.g)

    straight = optimise(TuningRequest('handling', 2, None, 'full',
                                      with_noise_levels(options, 'handling')), full_model,
                        **check_options('handling', 2))
    assert short.iterations == 1 and resumed.nit > short.iterations
    np.testing.assert_array_equal(resumed.x, straight.x)
    assert resumed.f == straight.f
    assert resumed.nit == straight.nit
    # The design to report is the best over the whole run, the bag's iterations included.
    np.testing.assert_array_equal(resumed.x_best, straight.x_best)
    assert resumed.best_iteration == straight.best_iteration
    # The resumed run counts the recorded runs plus its own.  A record is published
    # after its evaluation and before the gradient at that point, so the resumed run's
    # first gradient (2n = 4 runs) is the one the interrupted run never took: the totals
    # equal the uninterrupted run's.
    assert resumed.n_full_runs == straight.n_full_runs
