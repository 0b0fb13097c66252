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
                if node.describe_parameter(name).read_only:  # start-up only: refused
                    assert not result.successful and 'read-only' in result.reason, name
                    continue
                assert result.successful, (node.get_name(), name, result.reason)
                stored = node.get_parameter(name).value
                assert type(stored) is kinds[name] and stored == other, (name, stored)
            # Text is refused, naming the parameter.
            settable = [n for n in kinds if not node.describe_parameter(n).read_only]
            for name in settable[:1]:
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


#: Parameters that act when set; every other parameter of these nodes is read only
#: (read once at start-up).  use_sim_time is rclpy's own.
SETTABLE = {
    'coordinator': {'calibration_samples', 'fd_step', 'final_telemetry', 'use_sim_time'},
    'gradient_evaluator': {'default_samples', 'default_step', 'use_sim_time'},
    'full_vehicle_sim': {'valve_controller', 'telemetry_decimation', 'telemetry_rate',
                         'closed_loop_timeout_s', 'max_designs_per_request', 'use_sim_time'},
    'recorder': {'use_sim_time'},
    'valve_controller': {'use_sim_time'},
}


def test_every_parameter_has_a_value_and_start_up_ones_are_read_only(ros_context, tmp_path):
    """What ``ros2 param list/get/dump`` show: a value for every parameter.

    rclpy's get_parameters service answers a request naming an uninitialised parameter
    with no values at all, so one such parameter empties ``ros2 param dump``.
    """
    nodes = _nodes(ros_context, tmp_path)
    try:
        for node in nodes:
            names = node.list_parameters([], 0).names
            assert names, node.get_name()
            for parameter in node.get_parameters(names):
                assert parameter.type_ != Parameter.Type.NOT_SET, (node.get_name(),
                                                                   parameter.name)
            if node.get_name() in SETTABLE:
                read_only = {n for n in names if node.describe_parameter(n).read_only}
                assert set(names) - read_only == SETTABLE[node.get_name()], node.get_name()
        coordinator = nodes[0]
        assert coordinator.get_parameter('sim_workers').value == []  # every worker
        [result] = coordinator.set_parameters([Parameter('result_timeout_s', value=20.0)])
        assert not result.successful and 'read-only' in result.reason
    finally:
        for node in nodes:
            node.destroy_node()


def test_a_sim_workers_list_given_at_start_up_is_kept(ros_context):
    from suspension_tuning.nodes.coordinator import CoordinatorNode

    node = CoordinatorNode(context=ros_context, parameter_overrides=[
        Parameter('sim_workers', value=['/sim_a'])])
    try:
        assert node.get_parameter('sim_workers').value == ['/sim_a']
        assert node.pool.allow == ['/sim_a']
    finally:
        node.destroy_node()
