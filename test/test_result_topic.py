"""The result topic's own message type (``/optimisation/result``: OptimisationResult)."""

import pytest

pytestmark = pytest.mark.ros


def test_the_result_message_has_the_action_results_fields_one_for_one():
    # A field added to the action's result must be added to the message too, else the
    # topic (and so every bag) would lose it.
    from suspension_tuning_interfaces.action import Optimise
    from suspension_tuning_interfaces.msg import OptimisationResult

    assert (OptimisationResult.get_fields_and_field_types()
            == Optimise.Result.get_fields_and_field_types())


def test_the_published_result_carries_every_value_of_the_action_result():
    from suspension_tuning_interfaces.action import Optimise
    from suspension_tuning_interfaces.msg import IterationRecord

    from suspension_tuning.nodes.coordinator import result_topic_message

    result = Optimise.Result(success=True, message='converged', x=[0.25, 0.75], f=0.105,
                             g=[-0.01], feasible=True, best_iteration=4,
                             metric_names=['a_rms_driver_mps2'], metrics=[0.92],
                             history=[IterationRecord(iteration=4, f=0.105)],
                             n_full_runs=10, model_fingerprint='1a64536b7bd2c640')
    message = result_topic_message(result)
    for name in Optimise.Result.get_fields_and_field_types():
        assert getattr(message, name) == getattr(result, name), name
