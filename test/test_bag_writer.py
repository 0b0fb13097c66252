"""Bag layer: definitions, writer, tolerant reader, reindex; checked with two readers."""

import math
import random
import shutil
import struct
from pathlib import Path
from types import SimpleNamespace

import pytest
import yaml

TYPES = [
    'suspension_tuning_interfaces/msg/IterationRecord',
    'suspension_tuning_interfaces/msg/ValveState',
    'suspension_tuning_interfaces/msg/VehicleState',
    'suspension_tuning_interfaces/srv/EvaluateDesign_Event',
    'suspension_tuning_interfaces/srv/EvaluateGradient_Event',
    'suspension_tuning_interfaces/srv/Calibrate_Event',
    'suspension_tuning_interfaces/action/Optimise_FeedbackMessage',
    'suspension_tuning_interfaces/action/Optimise_Result',
    'action_msgs/msg/GoalStatusArray',
    'sensor_msgs/msg/Imu',
    'sensor_msgs/msg/JointState',
    'rosgraph_msgs/msg/Clock',
    'std_msgs/msg/String',
]


def sample_messages():
    """One filled message per type of TYPES (values chosen to be recognisable)."""
    from action_msgs.msg import GoalStatus, GoalStatusArray
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import Imu, JointState
    from std_msgs.msg import String
    from suspension_tuning_interfaces.action import Optimise
    from suspension_tuning_interfaces.msg import IterationRecord, ValveState, VehicleState
    from suspension_tuning_interfaces.srv import Calibrate, EvaluateDesign, EvaluateGradient

    record = IterationRecord(iteration=3, x=[0.25, 0.5], f=1.25, g=[-0.5], move_limit=0.125)
    event = EvaluateDesign.Event()
    event.request = [EvaluateDesign.Request(scenario='ride', n_vars=2, designs=[0.25, 0.5])]
    grad = EvaluateGradient.Event()
    grad.response = [EvaluateGradient.Response(success=True, df=[1.0, -2.0])]
    calib = Calibrate.Event()
    calib.request = [Calibrate.Request(scenario='handling', n_vars=4, n_samples=30)]
    feedback = Optimise.Impl.FeedbackMessage()
    feedback.feedback.latest = record
    result = Optimise.Result(success=True, x=[0.25, 0.5], f=1.25, g=[-0.5], history=[record])
    joint = JointState(name=['FL', 'FR'], position=[0.01, -0.02], effort=[4000.0, 4100.0])
    imu = Imu()
    imu.linear_acceleration.z = 9.81
    return {
        TYPES[0]: record,
        TYPES[1]: ValveState(step=7, front_spring=1),
        TYPES[2]: VehicleState(step=7, speed_mps=18.0, strut_pressure_pa=[4e6] * 4),
        TYPES[3]: event,
        TYPES[4]: grad,
        TYPES[5]: calib,
        TYPES[6]: feedback,
        TYPES[7]: result,
        TYPES[8]: GoalStatusArray(status_list=[GoalStatus(status=GoalStatus.STATUS_SUCCEEDED)]),
        TYPES[9]: imu,
        TYPES[10]: joint,
        TYPES[11]: Clock(),
        TYPES[12]: String(data='scenario: ride'),
    }


def topic_of(type_name):
    return '/' + type_name.replace('/', '_').lower()


def write_sample_bag(path, repeat=1, chunk_size=512 * 1024):
    """Every sample type on its own topic, `repeat` times, 10 ms apart (log time)."""
    from rclpy.serialization import serialize_message

    from suspension_tuning.bag.writer import BagWriter, qos_profile_dict

    expected = []
    with BagWriter(path, chunk_size=chunk_size) as bag:
        for type_name in TYPES:
            bag.add_topic(
                topic_of(type_name),
                type_name,
                [qos_profile_dict('reliable', 'transient_local', depth=1)],
            )
        bag.add_metadata('run_config', {'yaml': 'scenario: ride\n'})
        t = 1_700_000_000_000_000_000
        for k in range(repeat):
            for type_name, msg in sample_messages().items():
                data = serialize_message(msg)
                t += 10_000_000
                bag.write(topic_of(type_name), data, t, t - 1000, sequence=k)
                expected.append((topic_of(type_name), t, data))
    return expected


@pytest.mark.parametrize('type_name', TYPES)
def test_definition_has_the_top_text_first_and_each_dependency_once(type_name):
    from suspension_tuning.bag.definitions import SEPARATOR, definition_text

    text = definition_text(type_name)
    headers = [line for line in text.splitlines() if line.startswith('MSG: ')]
    assert not text.startswith(SEPARATOR)
    assert len(headers) == len(set(headers))
    # every dependency block is preceded by exactly the 80-'=' separator line and headed
    # with the name its field uses: two parts for a message (rosbag2: MSG:
    # std_msgs/Header), the full name for an action's part (pkg/action/T_Feedback: the
    # name that enters the type hash)
    lines = text.splitlines()
    for k, line in enumerate(lines):
        if line.startswith('MSG: '):
            assert lines[k - 1] == '=' * 80
            assert line.count('/') == 1 or line.split('/')[1] == 'action', line


def test_composition_reproduces_rosbag2s_own_expected_text():
    from suspension_tuning.bag.definitions import _compose, referenced_names

    # rosbag2_test_msgdefs (ros2/rosbag2, jazzy): ComplexMsg.msg is one field of BasicMsg,
    # BasicMsg.msg is "float32 c"; test_local_message_definition_source.cpp,
    # can_find_msg_deps, expects exactly the string below for ComplexMsg.
    files = {
        'rosbag2_test_msgdefs/msg/ComplexMsg': 'rosbag2_test_msgdefs/BasicMsg b\n',
        'rosbag2_test_msgdefs/msg/BasicMsg': 'float32 c\n',
    }

    def own(key):
        text = files[key]
        names = referenced_names(text, key.split('/')[0])
        return text, {n: n.replace('/', '/msg/') for n in names}

    assert _compose('rosbag2_test_msgdefs/msg/ComplexMsg', own) == (
        'rosbag2_test_msgdefs/BasicMsg b\n'
        '\n'
        '================================================================================\n'
        'MSG: rosbag2_test_msgdefs/BasicMsg\n'
        'float32 c\n'
    )


@pytest.mark.parametrize(
    ('type_name', 'headers'),
    [
        # Imu.msg uses std_msgs/Header, geometry_msgs/Quaternion, geometry_msgs/Vector3
        # (three Vector3 fields, one section); rosbag2 keeps a text's field types in a
        # std::set (sorted) and appends each one's own dependencies right after it
        # (Header -> builtin_interfaces/Time).
        (
            'sensor_msgs/msg/Imu',
            [
                'geometry_msgs/Quaternion',
                'geometry_msgs/Vector3',
                'std_msgs/Header',
                'builtin_interfaces/Time',
            ],
        ),
        # GoalStatusArray.msg: GoalStatus[] (relative: action_msgs/GoalStatus);
        # GoalStatus.msg: GoalInfo (relative); GoalInfo.msg: builtin_interfaces/Time,
        # unique_identifier_msgs/UUID, in that sorted order.
        (
            'action_msgs/msg/GoalStatusArray',
            [
                'action_msgs/GoalStatus',
                'action_msgs/GoalInfo',
                'builtin_interfaces/Time',
                'unique_identifier_msgs/UUID',
            ],
        ),
        # a service event (rosidl composition: info, request[<=1], response[<=1]); the
        # request and response sections are named as the event's fields spell them
        (
            'suspension_tuning_interfaces/srv/Calibrate_Event',
            [
                'service_msgs/ServiceEventInfo',
                'builtin_interfaces/Time',
                'suspension_tuning_interfaces/Calibrate_Request',
                'suspension_tuning_interfaces/Calibrate_Response',
            ],
        ),
    ],
)
def test_dependencies_are_named_as_referenced_in_rosbag2s_order(type_name, headers):
    from suspension_tuning.bag.definitions import definition_text, own_text

    text = definition_text(type_name)
    assert [ln[5:] for ln in text.splitlines() if ln.startswith('MSG: ')] == headers
    # texts are appended as they are: the installed file verbatim, then a newline
    if type_name.endswith('/Imu'):
        assert text.startswith(own_text(type_name) + '\n' + '=' * 80 + '\n')


def test_service_event_definition_is_info_request_response():
    from suspension_tuning.bag.definitions import definition_text

    text = definition_text('suspension_tuning_interfaces/srv/EvaluateDesign_Event')
    top = text.split('=' * 80)[0].split('\n')
    # composition of a service event (rosidl, service_msgs): info, request[<=1], response[<=1]
    assert top[:3] == [
        'service_msgs/ServiceEventInfo info',
        'suspension_tuning_interfaces/EvaluateDesign_Request[<=1] request',
        'suspension_tuning_interfaces/EvaluateDesign_Response[<=1] response',
    ]
    assert '\nMSG: service_msgs/ServiceEventInfo\n' in text
    assert '\nMSG: suspension_tuning_interfaces/EvaluateDesign_Request\n' in text
    assert '\nMSG: builtin_interfaces/Time\n' in text


def test_unknown_type_raises_definition_not_found():
    from suspension_tuning.bag.definitions import DefinitionNotFoundError, definition_text

    with pytest.raises(DefinitionNotFoundError):
        definition_text('no_such_pkg/msg/Nothing')
    with pytest.raises(ValueError):
        definition_text('not a type')


def test_bag_has_ros2_profile_cdr_channels_qos_statistics_and_rosbag2_record(tmp_path):
    from mcap.reader import make_reader

    write_sample_bag(tmp_path / 'bag', repeat=2)
    files = sorted(p.name for p in (tmp_path / 'bag').iterdir())
    assert files == ['bag_0.mcap', 'metadata.yaml']
    with open(tmp_path / 'bag' / 'bag_0.mcap', 'rb') as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        assert summary.statistics.message_count == 2 * len(TYPES)
        assert summary.statistics.chunk_count >= 1
        assert all(c.compression == 'zstd' for c in summary.chunk_indexes)
        # ros2idl for the service events: ros2msg has no name for their parts that
        # rosbags keeps
        assert {s.name: s.encoding for s in summary.schemas.values()} == {
            name: 'ros2idl' if '/srv/' in name else 'ros2msg' for name in TYPES}
        for channel in summary.channels.values():
            assert channel.message_encoding == 'cdr'
            qos = yaml.safe_load(channel.metadata['offered_qos_profiles'])
            assert qos[0]['reliability'] == 'reliable'
            assert qos[0]['durability'] == 'transient_local'
            assert channel.metadata['topic_type_hash'].startswith('RIHS01_')
        records = {m.name: m.metadata for m in reader.iter_metadata()}
    assert records['run_config'] == {'yaml': 'scenario: ride\n'}
    serialized = yaml.safe_load(records['rosbag2']['serialized_metadata'])
    assert serialized['message_count'] == 2 * len(TYPES)
    info = yaml.safe_load((tmp_path / 'bag' / 'metadata.yaml').read_text())
    info = info['rosbag2_bagfile_information']
    assert info['version'] == 9
    assert info['storage_identifier'] == 'mcap'
    assert info['relative_file_paths'] == ['bag_0.mcap']
    assert info['message_count'] == 2 * len(TYPES)
    # 26 messages 10 ms apart: 25 intervals = 250 ms
    assert info['duration']['nanoseconds'] == 250_000_000
    counts = {
        t['topic_metadata']['name']: t['message_count'] for t in info['topics_with_message_count']
    }
    assert counts == {topic_of(t): 2 for t in TYPES}


def test_every_message_decodes_with_mcap_ros2_and_equals_what_was_written(tmp_path):
    from suspension_tuning.bag.reader import decode, read_messages

    expected = write_sample_bag(tmp_path / 'bag')
    contents = read_messages(tmp_path / 'bag')
    assert contents.complete and contents.stop_reason == ''
    assert [(m.topic, m.log_time_ns, m.data) for m in contents.messages] == expected
    assert all(m.publish_time_ns == m.log_time_ns - 1000 for m in contents.messages)
    decoded = {m.topic: decode(contents, m) for m in contents.messages}
    assert decoded[topic_of(TYPES[0])].x == [0.25, 0.5]
    event = decoded[topic_of(TYPES[3])]
    assert event.request[0].scenario == 'ride'
    assert list(event.request[0].designs) == [0.25, 0.5]
    assert list(decoded[topic_of(TYPES[4])].response[0].df) == [1.0, -2.0]
    assert decoded[topic_of(TYPES[6])].feedback.latest.move_limit == 0.125
    assert decoded[topic_of(TYPES[7])].history[0].iteration == 3
    assert decoded[topic_of(TYPES[8])].status_list[0].status == 4  # STATUS_SUCCEEDED
    assert decoded[topic_of(TYPES[10])].name == ['FL', 'FR']
    assert decoded[topic_of(TYPES[12])].data == 'scenario: ride'


def plain(value):
    """A message decoded by mcap-ros2-support as the JSON values check_bag.mjs prints."""
    if isinstance(value, SimpleNamespace):  # mcap-ros2-support: fields in __slots__
        return {k: plain(getattr(value, k)) for k in value.__slots__}
    if isinstance(value, list | tuple | bytes | bytearray):
        return [plain(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return 'NaN' if math.isnan(value) else ('Infinity' if value > 0 else '-Infinity')
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 2**53 - 1:
        return str(value)
    return value


def foxglove_time(value):
    """Foxglove's time values as the message's fields: from an IDL schema it decodes
    builtin_interfaces/msg/Time as its time type, ``{sec, nsec}``."""
    if isinstance(value, dict):
        if set(value) == {'sec', 'nsec'}:
            return {'sec': value['sec'], 'nanosec': value['nsec']}
        return {k: foxglove_time(v) for k, v in value.items()}
    if isinstance(value, list):
        return [foxglove_time(v) for v in value]
    return value


def test_every_type_decodes_with_foxglove_to_the_values_mcap_ros2_reads(
    foxglove_check, tmp_path
):
    from suspension_tuning.bag.reader import decode, read_messages

    write_sample_bag(tmp_path / 'bag', repeat=2)
    [result] = foxglove_check([tmp_path / 'bag'], messages=True)
    errors = {c['topic']: c['error'] for c in result['channels'] if c['error']}
    assert result['complete'] and not errors
    assert result['ok']
    contents = read_messages(tmp_path / 'bag')
    channels = {c['topic']: c for c in result['channels']}
    assert set(channels) == {topic_of(t) for t in TYPES}
    for topic, channel in channels.items():
        assert channel['decoded'] == channel['messages'] == 2
        ours = [plain(decode(contents, m)) for m in contents.on(topic)]
        assert [foxglove_time(m['message']) for m in channel['decoded_messages']] == ours, topic
    event = channels[topic_of(TYPES[3])]['decoded_messages'][0]['message']
    assert event['request'][0]['designs'] == [0.25, 0.5]  # as written in sample_messages


LEGACY = Path(__file__).parent / 'fixtures' / 'legacy_schemas'


def test_a_bag_with_the_older_schema_headers_reads_inspects_and_reindexes(tmp_path):
    from suspension_tuning.bag.definitions import definition_text, rosbag2_form
    from suspension_tuning.bag.reader import decode, read_messages, reindex
    from suspension_tuning.inspect_bag import last_iteration, summary

    # fixtures/legacy_schemas: messages of a make-demo ride run, schemas as the writer
    # stored them before the rosbag2 layout (MSG: pkg/msg/Name, order of appearance)
    old = read_messages(LEGACY)
    imu = next(c for c in old.channels.values() if c.type == 'sensor_msgs/msg/Imu')
    assert '\nMSG: std_msgs/msg/Header\n' in imu.definition
    before = [plain(decode(old, m)) for m in old.messages]
    info = summary(LEGACY)
    assert info['complete'] and info['run_config']['scenario'] == 'ride'
    assert last_iteration(LEGACY) is not None
    shutil.copytree(LEGACY, tmp_path / 'bag')
    reindex(tmp_path / 'bag')
    new = read_messages(tmp_path / 'bag')
    assert [plain(decode(new, m)) for m in new.messages] == before
    for channel in new.channels.values():
        stored = next(c for c in old.channels.values() if c.topic == channel.topic)
        assert channel.definition == rosbag2_form(stored.type, stored.definition)
        assert '/msg/' not in ''.join(
            ln for ln in channel.definition.splitlines() if ln.startswith('MSG: ')
        )
    # standard types unchanged since the recording: the rewrite is what the writer
    # writes today, byte for byte
    for channel in new.channels.values():
        if channel.type in ('sensor_msgs/msg/Imu', 'action_msgs/msg/GoalStatusArray'):
            assert channel.definition == definition_text(channel.type)
        # a definition in rosbag2's layout is left as it is (reindex twice: no change)
        assert rosbag2_form(channel.type, channel.definition) == channel.definition


def test_reindexed_older_bag_decodes_with_foxglove(foxglove_check, tmp_path):
    from suspension_tuning.bag.reader import reindex

    [old] = foxglove_check([LEGACY])
    errors = {c['topic']: c['error'] for c in old['channels'] if c['error']}
    # Foxglove's parser matches dependency names exactly: the field std_msgs/Header
    # finds no section headed MSG: std_msgs/msg/Header
    assert "'std_msgs/Header' but found 0" in errors['/full_vehicle_sim/telemetry/imu']
    shutil.copytree(LEGACY, tmp_path / 'bag')
    reindex(tmp_path / 'bag')
    [new] = foxglove_check([tmp_path / 'bag'])
    assert new['ok'], {c['topic']: c['error'] for c in new['channels'] if c['error']}
    assert sum(c['decoded'] for c in new['channels']) == sum(
        c['messages'] for c in old['channels']
    )


def rosbags_decode(typestore, raw, type_name):
    """Decode with rosbags' CDR deserialiser; return (message, trailing bytes).

    rosbags' own ``deserialize_cdr`` also rejects messages with more than 3 bytes after
    the CDR payload; Fast DDS (rmw_fastrtps, Jazzy) serialises some types with a few
    unused bytes at the end, so the payload end is returned and checked by the caller
    instead.  It sizes the buffer as if every float64 sequence were aligned to 8 bytes,
    which an empty one is not: up to 4 unused bytes per empty float64 sequence
    (:func:`empty_float64_sequences`; 0 when every sequence holds a value, measured).
    """
    msgdef = typestore.get_msgdef(type_name)
    assert bytes(raw[:2]) == b'\x00\x01'  # CDR little endian encapsulation
    message, pos = msgdef.deserialize_cdr_le(raw[4:], 0, msgdef.cls, typestore)
    return message, len(raw) - 4 - pos


def empty_float64_sequences(message) -> int:
    """Empty float64 sequences of a rosbags-decoded message, nested ones included."""
    import dataclasses

    import numpy as np

    count = 0
    for field in dataclasses.fields(message):
        value = getattr(message, field.name)
        if isinstance(value, np.ndarray) and value.dtype == np.float64 and value.size == 0:
            count += 1
        elif dataclasses.is_dataclass(value):
            count += empty_float64_sequences(value)
        elif isinstance(value, list):
            count += sum(empty_float64_sequences(v) for v in value
                         if dataclasses.is_dataclass(v))
    return count


def test_bag_opens_with_rosbags_anyreader_which_checks_every_type_hash(tmp_path):
    """rosbags' AnyReader recomputes each channel's RIHS01 hash from its schema text and
    refuses a mismatch: every text names each type in full (action parts pkg/action/T,
    service events as ros2idl), so every hash is the installed interface's."""
    from rosbags.highlevel import AnyReader

    from suspension_tuning.bag.definitions import type_hash

    write_sample_bag(tmp_path / 'bag', repeat=2)
    with AnyReader([tmp_path / 'bag']) as reader:
        assert sum(c.msgcount for c in reader.connections) == 2 * len(TYPES)
        for connection in reader.connections:
            assert connection.digest == type_hash(connection.msgtype) != ''
            assert reader.typestore.hash_rihs01(connection.msgtype) == connection.digest
            kind = connection.msgtype.split('/')[1]
            assert connection.msgdef.format.name == ('IDL' if kind == 'srv' else 'MSG')
            assert connection.ext.offered_qos_profiles[0].depth == 1
        decoded = {}
        for connection, _, raw in reader.messages():
            message, trailing = rosbags_decode(reader.typestore, raw, connection.msgtype)
            # 16 measured on every type; 4 per empty float64 sequence where a message has
            # more than 4 of them (the Optimise_Result of sample_messages has 8)
            bound = max(16, 4 * empty_float64_sequences(message))
            assert 0 <= trailing <= bound, (connection.topic, trailing)
            decoded[connection.topic] = message
    assert list(decoded[topic_of(TYPES[0])].x) == [0.25, 0.5]
    assert decoded[topic_of(TYPES[3])].request[0].scenario == 'ride'
    assert decoded[topic_of(TYPES[6])].feedback.latest.iteration == 3  # the record's
    assert decoded[topic_of(TYPES[7])].history[0].iteration == 3
    assert decoded[topic_of(TYPES[12])].data == 'scenario: ride'


def chunk_ends(mcap_bytes):
    """Byte offsets just after each Chunk record of an MCAP file (opcode 0x06)."""
    ends, pos = [], 8
    while pos + 9 <= len(mcap_bytes):
        opcode, length = struct.unpack_from('<BQ', mcap_bytes, pos)
        pos += 9 + length
        if opcode == 0x06:
            ends.append(pos)
        if opcode == 0x02:  # footer
            break
    return ends


def test_bag_cut_at_random_bytes_reads_to_its_last_complete_chunk(tmp_path):
    from suspension_tuning.bag.reader import read_messages

    # small chunks (2 KiB) so that the file has many: each of the 13 types is 50-400 B
    expected = write_sample_bag(tmp_path / 'bag', repeat=20, chunk_size=2048)
    data = (tmp_path / 'bag' / 'bag_0.mcap').read_bytes()
    full = read_messages(tmp_path / 'bag')
    assert full.complete and full.message_count == len(expected) == 260
    ends = chunk_ends(data)
    assert len(ends) == full.chunks >= 10
    rng = random.Random(8)  # seeded: the same cuts every run
    cuts = sorted(rng.randrange(9, len(data)) for _ in range(12))
    for cut in cuts:
        partial = tmp_path / f'cut_{cut}.mcap'
        partial.write_bytes(data[:cut])
        contents = read_messages(partial)
        complete_chunks = sum(1 for e in ends if e <= cut)
        assert not contents.complete
        assert contents.chunks == complete_chunks, cut
        # messages are exactly those of the complete chunks: a prefix of what was written
        n = contents.message_count
        assert [(m.topic, m.log_time_ns, m.data) for m in contents.messages] == expected[:n]
        if complete_chunks == len(ends):
            assert n == len(expected)
        else:
            assert n < len(expected)


def test_reindex_repairs_a_truncated_bag_into_a_complete_one(tmp_path):
    from rosbags.rosbag2 import Reader

    from suspension_tuning.bag.reader import read_messages, reindex

    expected = write_sample_bag(tmp_path / 'bag', repeat=10, chunk_size=2048)
    data = (tmp_path / 'bag' / 'bag_0.mcap').read_bytes()
    (tmp_path / 'bag' / 'metadata.yaml').unlink()  # as a killed recorder leaves it
    ends = chunk_ends(data)
    (tmp_path / 'bag' / 'bag_0.mcap').write_bytes(data[: ends[3] + 100])
    recovered = read_messages(tmp_path / 'bag').message_count
    assert 0 < recovered < len(expected)
    reindex(tmp_path / 'bag')
    repaired = read_messages(tmp_path / 'bag')
    assert repaired.complete and repaired.message_count == recovered
    assert repaired.metadata['run_config'] == {'yaml': 'scenario: ride\n'}
    with Reader(tmp_path / 'bag') as reader:
        assert reader.message_count == recovered
    shutil.rmtree(tmp_path / 'bag')


def test_writer_rejects_bad_input(tmp_path):
    from suspension_tuning.bag.writer import BagWriter, qos_profile_dict

    with BagWriter(tmp_path / 'bag') as bag:
        bag.add_topic('/a', 'std_msgs/msg/String')
        with pytest.raises(ValueError, match='not registered'):
            bag.write('/b', b'\x00\x01\x00\x00', 1)
        with pytest.raises(ValueError, match='already has type'):
            bag.add_topic('/a', 'std_msgs/msg/Float64')
        with pytest.raises(ValueError, match='negative'):
            bag.write('/a', b'\x00\x01\x00\x00', -1)
    with pytest.raises(ValueError, match='not empty'):
        BagWriter(tmp_path / 'bag')
    with pytest.raises(ValueError, match='reliability'):
        qos_profile_dict(reliability='sometimes')
