"""The sample run kept in bags/sample (`make sample-bag`: the ride run of `make demo`) opens,
inspects and decodes cleanly, also with Foxglove's libraries."""

from pathlib import Path

SAMPLE = Path(__file__).resolve().parents[1] / 'bags' / 'sample'


def test_sample_bag_holds_a_complete_ride_optimisation():
    from suspension_tuning.inspect_bag import summary

    info = summary(SAMPLE)
    assert info['complete']
    assert info['run_config']['scenario'] == 'ride'
    assert info['run_config']['n_vars'] == 4
    optimum = info['optimum']
    assert optimum['success']
    # The result's iteration count and run counts equal the progress records'.
    assert optimum['iterations'] == len(info['iterations']) - 1
    assert info['evaluations']['n_full_runs'] == optimum['n_full_runs']
    # Telemetry of the optimum: 15 s ride at 250 Hz, every 2nd sample (config files).
    assert info['topics']['/full_vehicle_sim/telemetry/imu']['count'] == 1875


def test_sample_bag_decodes_with_a_reader_we_did_not_write():
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    # rosbags' AnyReader registers every connection's type at open and trips over the
    # service-event type names (it files srv types under pkg/srv/msg/...); the plain
    # Reader with the bag's own ros2msg schemas decodes the optimisation topics.
    typestore = get_typestore(Stores.EMPTY)
    count = 0
    with Reader(SAMPLE) as reader:
        wanted = [c for c in reader.connections if c.topic == '/optimisation/progress']
        for connection in wanted:
            typestore.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        for connection, _, raw in reader.messages(connections=wanted):
            msg = typestore.deserialize_cdr(raw, connection.msgtype)
            assert len(msg.x) == 4 and msg.n_full_runs >= 1
            count += 1
    assert count >= 2


def test_every_message_of_the_sample_bag_decodes_with_foxglove(foxglove_check):
    from suspension_tuning.bag.reader import read_messages

    [result] = foxglove_check([SAMPLE])
    errors = {c['topic']: c['error'] for c in result['channels'] if c['error']}
    assert result['complete'] and not errors
    assert result['ok']
    # every message the bag holds (Python's reader counts them independently)
    assert sum(c['decoded'] for c in result['channels']) == read_messages(SAMPLE).message_count
    topics = {c['topic']: c['schema_name'] for c in result['channels']}
    assert topics['/full_vehicle_sim/telemetry/imu'] == 'sensor_msgs/msg/Imu'
    assert topics['/coordinator/optimise/_action/feedback'].endswith('Optimise_FeedbackMessage')
    assert topics['/full_vehicle_sim/evaluate/_service_event'].endswith('EvaluateDesign_Event')
