"""Numeric node parameters take what users write (nodes/_parameters.py).

``call_timeout_s: 30`` (an int for a float parameter) must not stop a node; a whole
float is taken for a count; anything else is refused naming the parameter, at start-up
and when set at run time.
"""

import pytest
from rclpy.parameter import Parameter

pytestmark = pytest.mark.ros


def _nodes(context, tmp_path):
    from suspension_tuning.nodes.coordinator import CoordinatorNode
    from suspension_tuning.nodes.full_vehicle_sim import FullVehicleSimNode
    from suspension_tuning.nodes.gradient_evaluator import GradientEvaluatorNode
    from suspension_tuning.nodes.recorder import RecorderNode
    from suspension_tuning.nodes.replay import ReplayNode
    from suspension_tuning.nodes.valve_controller import ValveControllerNode

    recorder = [Parameter('output_dir', value=str(tmp_path))]
    return [make(context=context, parameter_overrides=recorder if make is RecorderNode else [])
            for make in (CoordinatorNode, FullVehicleSimNode, GradientEvaluatorNode,
                         RecorderNode, ReplayNode, ValveControllerNode)]


def test_every_numeric_node_parameter_takes_an_int_or_a_float(ros_context, tmp_path):
    nodes = _nodes(ros_context, tmp_path)
    try:
        for node in nodes:
            numeric = {name: p.value for name, p in node._parameters.items()
                       if isinstance(p.value, (int, float)) and not isinstance(p.value, bool)}
            kinds = node._numeric_parameter_kinds
            assert set(numeric) == set(kinds), node.get_name()  # none declared otherwise
            for name, value in numeric.items():
                other = int(value) if isinstance(value, float) else float(value)
                if isinstance(value, float) and not value.is_integer():
                    other = float(value)  # no int means the same: set the float again
                [result] = node.set_parameters([Parameter(name, value=other)])
                assert result.successful, (node.get_name(), name, result.reason)
                stored = node.get_parameter(name).value
                assert type(stored) is kinds[name] and stored == other, (name, stored)
            # Text is refused, naming the parameter.
            name = next(iter(kinds))
            [result] = node.set_parameters([Parameter(name, value='30')])
            assert not result.successful and f'parameter {name} must be' in result.reason
    finally:
        for node in nodes:
            node.destroy_node()


def test_an_int_for_a_float_and_a_whole_float_for_a_count_start_a_node(ros_context):
    from suspension_tuning.nodes._parameters import ParameterError
    from suspension_tuning.nodes.coordinator import CoordinatorNode

    node = CoordinatorNode(context=ros_context, parameter_overrides=[
        Parameter('call_timeout_s', value=30), Parameter('calibration_samples', value=12.0)])
    try:
        assert node.get_parameter('call_timeout_s').value == 30.0
        assert isinstance(node.get_parameter('call_timeout_s').value, float)
        assert node.get_parameter('calibration_samples').value == 12
        assert isinstance(node.get_parameter('calibration_samples').value, int)
    finally:
        node.destroy_node()
    for name, value, message in [
            ('calibration_samples', 12.5, 'must be a whole number'),
            ('call_timeout_s', '30', 'must be a number'),
            ('call_timeout_s', True, 'must be a number')]:
        with pytest.raises(ParameterError, match=f'parameter coordinator.{name} {message}'):
            CoordinatorNode(context=ros_context,
                            parameter_overrides=[Parameter(name, value=value)])
