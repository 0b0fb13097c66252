"""The demo's exit status: an optimiser's own stop is a result, anything else a failure."""

from suspension_tuning.demo import optimiser_stopped


def test_demo_reports_an_optimiser_stop_and_fails_on_anything_else():
    # Dynamic-Q's stops (optim/dynamic_q.py STATUS_MESSAGES 0-4), with the suffix the
    # result adds at an infeasible final point
    assert optimiser_stopped('converged: step shorter than xtol')
    assert optimiser_stopped(
        'stopped: maximum number of iterations reached (final point infeasible)'
    )
    assert optimiser_stopped('stopped: move limit below rho_min at an infeasible point')
    # stopped from outside, or no optimisation at all: the demo failed
    assert not optimiser_stopped('stopped by the callback or the caller')
    assert not optimiser_stopped('bad goal: n_vars must be 2 or 4')
    assert not optimiser_stopped('stopped: ROS shut down under the goal')
