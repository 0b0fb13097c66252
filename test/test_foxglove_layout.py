"""The Foxglove layout of the package (config/foxglove_layout.json) against the graph.

Every topic a plot of the layout reads is one the graph's nodes publish, and every field
path exists in that topic's message definition and ends on a number, so the layout
cannot rot when a message or a topic changes.
"""

import json
import re

import pytest

from suspension_tuning.paths import config_dir

pytestmark = pytest.mark.ros

LAYOUT = config_dir() / 'foxglove_layout.json'
#: A message path of a Foxglove plot: topic, then fields with an optional [index].
PATH = re.compile(r'^(?P<topic>/[A-Za-z0-9_/]+)\.(?P<fields>[A-Za-z0-9_.\[\]]+)$')
FIELD = re.compile(r'^(?P<name>[A-Za-z0-9_]+)(\[(?P<index>\d+)\])?$')
NUMBERS = {'double', 'float', 'int8', 'uint8', 'int16', 'uint16', 'int32', 'uint32', 'int64',
           'uint64', 'boolean', 'octet'}


def layout_paths(layout: dict) -> list[tuple[str, str]]:
    """(panel, message path) of every plotted path and custom x axis of the layout."""
    out = []
    for panel, config in layout['configById'].items():
        for path in config.get('paths', []):
            out.append((panel, path['value']))
        if config.get('xAxisVal') == 'custom':
            out.append((panel, config['xAxisPath']['value']))
    return out


def panels_in_tree(node) -> list[str]:
    if isinstance(node, str):
        return [node]
    return panels_in_tree(node['first']) + panels_in_tree(node['second'])


def resolve(message_type, fields: str, sequence_lengths: dict[str, int]) -> str:
    """The type of the leaf a field path names in ``message_type``; AssertionError if none."""
    message = message_type()
    parts = fields.split('.')
    for k, part in enumerate(parts):
        match = FIELD.match(part)
        assert match, f'bad field {part!r}'
        name, index = match['name'], match['index']
        types = message.get_fields_and_field_types()
        assert name in types, f'{type(message).__name__} has no field {name!r} ({sorted(types)})'
        kind = types[name]
        if index is not None:
            array = re.match(r'^(sequence<(?P<seq>[^,>]+)(, \d+)?>|(?P<arr>[a-z0-9_]+)\[\d+\])$',
                             kind)
            assert array, f'{name} is a {kind}, not an array: [{index}] does not apply'
            length = sequence_lengths.get(name)
            assert length is None or int(index) < length, f'{name}[{index}]: {length} entries'
            kind = array['seq'] or array['arr']
        if k < len(parts) - 1:
            message = getattr(message, name)
    return kind


def test_foxglove_layout_plots_only_topics_and_fields_the_graph_publishes(ros_context):
    from suspension_tuning import telemetry
    from suspension_tuning.graph import build_nodes

    layout = json.loads(LAYOUT.read_text())
    assert sorted(panels_in_tree(layout['layout'])) == sorted(layout['configById'])
    nodes = build_nodes(workers=1, record=False, context=ros_context)
    try:
        published = {pub.topic_name: pub.msg_type for node in nodes for pub in node.publishers}
    finally:
        for node in nodes:
            node.destroy_node()
    # JointState arrays hold one entry per strut and per tyre (telemetry.STRUTS, TYRES)
    lengths = {'/full_vehicle_sim/telemetry/struts': {'effort': len(telemetry.STRUTS),
                                                      'position': len(telemetry.STRUTS)},
               '/full_vehicle_sim/telemetry/tyres': {'effort': len(telemetry.TYRES),
                                                     'position': len(telemetry.TYRES)}}
    paths = layout_paths(layout)
    assert len(paths) >= 20  # seats 4, roll 2, valves 8, struts 4, tyres 4, iterations 3
    for panel, path in paths:
        match = PATH.match(path)
        assert match, f'{panel}: {path!r} is not a topic.field path'
        topic = match['topic']
        assert topic in published, f'{panel}: {topic} is not published by the graph'
        leaf = resolve(published[topic], match['fields'], lengths.get(topic, {}))
        assert leaf in NUMBERS, f'{panel}: {path} ends on a {leaf}, not a number'


def test_foxglove_layout_shows_a_run_at_a_glance():
    layout = json.loads(LAYOUT.read_text())
    values = {path for _, path in layout_paths(layout)}
    telemetry = '/full_vehicle_sim/telemetry'
    for wanted in (f'{telemetry}/seat/driver.accel.linear.z',       # seat, unweighted
                   f'{telemetry}/seat/driver_wb.accel.linear.z',    # seat, W_b
                   f'{telemetry}/attitude.vector.x',                # roll angle
                   f'{telemetry}/imu.angular_velocity.x',           # roll rate
                   '/suspension/valve_command.front_spring',        # valve command
                   '/suspension/valve_state.front_spring',          # against its state
                   f'{telemetry}/struts.effort[0]',                 # strut force
                   f'{telemetry}/tyres.effort[3]',                  # tyre normal force
                   '/optimisation/progress.f', '/optimisation/progress.max_violation'):
        assert wanted in values, wanted
    tyres = next(c for c in layout['configById'].values() if 'tyres.effort' in
                 c['paths'][0]['value'])
    assert tyres['minYValue'] == 0  # the plot's floor is Fz = 0, the lift-off of eq. 11
    # telemetry is published as a burst after the run: plotted on its simulated time
    for config in layout['configById'].values():
        for path in config['paths']:
            if path['value'].startswith(telemetry) or '/valve_' in path['value']:
                assert path['timestampMethod'] == 'headerStamp', path
