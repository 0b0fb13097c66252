"""Numeric node parameters that take what users write: ``30`` or ``30.0``.

rclpy fixes a parameter's type by its default: ``call_timeout_s: 30`` in a parameters
file, for a parameter declared with 600.0, would stop the node with
InvalidParameterTypeException.  :func:`declare_numbers` declares numeric parameters so
that an integer is taken where a float is meant, and a whole float (``16.0``) where an
integer is; the stored value has the declared kind, so the nodes read it as before.
Anything else (a string, a Boolean, ``16.5`` for a count) is refused with a message
naming the parameter, at start-up (:class:`ParameterError`) and when set at run time.
"""

from __future__ import annotations

from collections.abc import Mapping

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter


class ParameterError(ValueError):
    """A node parameter whose value cannot be used (the message names it)."""


def _normalised(name: str, value: object, kind: type) -> float | int:
    """``value`` as a ``kind`` (float or int), or ParameterError."""
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if kind is float and number:
        return float(value)
    if kind is int and number and float(value).is_integer():
        return int(value)
    expected = 'a number' if kind is float else 'a whole number'
    raise ParameterError(f'parameter {name} must be {expected} (e.g. '
                         f'{"30 or 30.0" if kind is float else "16"}), got {value!r}')


def declare_numbers(node: Node, defaults: Mapping[str, float | int]) -> None:
    """Declare numeric parameters of ``node`` that take an int or a float alike.

    Parameters
    ----------
    node : rclpy.node.Node
        The node (its overrides, e.g. from ``--params-file``, apply as usual).
    defaults : mapping of str to float or int
        Each parameter's default; its type is the parameter's kind.

    Raises
    ------
    ParameterError
        A value given for one of them is not a number of that kind.
    """
    kinds: dict[str, type] = getattr(node, '_numeric_parameter_kinds', None) or {}
    first = not kinds
    for name, default in defaults.items():
        kind = int if isinstance(default, int) and not isinstance(default, bool) else float
        node.declare_parameter(name, default, ParameterDescriptor(dynamic_typing=True))
        value = node.get_parameter(name).value
        normal = _normalised(f'{node.get_name()}.{name}', value, kind)
        if type(value) is not kind:
            node.set_parameters([Parameter(name, value=normal)])
        kinds[name] = kind
    node._numeric_parameter_kinds = kinds  # noqa: SLF001 - shared by the callbacks below
    if not first:
        return

    def convert(parameters: list[Parameter]) -> list[Parameter]:
        out = []
        for parameter in parameters:
            kind = kinds.get(parameter.name)
            try:
                value = _normalised(parameter.name, parameter.value, kind) if kind else None
            except ParameterError:
                value = None  # refused below, with the reason
            out.append(parameter if value is None else Parameter(parameter.name, value=value))
        return out

    def check(parameters: list[Parameter]) -> SetParametersResult:
        for parameter in parameters:
            kind = kinds.get(parameter.name)
            if kind is not None:
                try:
                    _normalised(parameter.name, parameter.value, kind)
                except ParameterError as error:
                    return SetParametersResult(successful=False, reason=str(error))
        return SetParametersResult(successful=True)

    node.add_pre_set_parameters_callback(convert)
    node.add_on_set_parameters_callback(check)


def read_only(node: Node, names: list[str]) -> None:
    """Mark declared parameters of ``node`` read-only: they take effect at start-up only.

    Their values still come from ``--params-file`` or ``-p`` at start; ``ros2 param set``
    is then refused ("Trying to set a read-only parameter"), instead of being accepted
    without effect.  ``ros2 param describe`` shows the flag.
    """
    for name in names:
        old = node.describe_parameter(name)  # the node's own object: not to be changed
        node.set_descriptor(name, ParameterDescriptor(
            type=old.type, description=old.description,
            additional_constraints=old.additional_constraints, read_only=True,
            dynamic_typing=old.dynamic_typing, floating_point_range=old.floating_point_range,
            integer_range=old.integer_range))


def declare_string_array(node: Node, name: str) -> list[str]:
    """Declare a string-array parameter whose default is the empty array; its value.

    rclpy infers a parameter's type from its default, and an empty list has none (it
    reads as a byte array), while a parameter declared with a type and no value is
    uninitialised: rclpy's ``get_parameters`` service then answers a request naming it
    with nothing at all (``ros2 param get``: "Parameter not set", ``ros2 param dump``:
    an empty node).  So the parameter is declared by type and then set to ``[]``
    unless an override gave it a value.
    """
    parameter = node.declare_parameter(name, Parameter.Type.STRING_ARRAY)
    if parameter.type_ == Parameter.Type.NOT_SET:
        node.set_parameters([Parameter(name, Parameter.Type.STRING_ARRAY, [])])
    return list(node.get_parameter(name).value)
