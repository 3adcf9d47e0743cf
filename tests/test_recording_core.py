"""MCAP writing and reading without DDS: full ros2msg definitions that mcap_ros2 decodes,
the threaded sink (publish time = header stamp), columns by seq, one-line errors."""
import pytest

from eha_ros.core.io import recording
from eha_ros.core.config.cli import UsageError
from eha_ros.core.io.mcap_sink import McapSink, stamp_ns
from ros_util import MSG_TYPES, fill

msgdefs = pytest.importorskip('eha_ros.nodes.msgdefs')
serialize = pytest.importorskip('rclpy.serialization').serialize_message

TYPES = [f'eha_msgs/msg/{t}' for t in MSG_TYPES] + ['diagnostic_msgs/msg/DiagnosticArray',
                                                    'rosgraph_msgs/msg/Clock']


@pytest.mark.parametrize('type_name', TYPES)
def test_definition_decodes_what_rclpy_serialises(type_name, tmp_path):
    cls = msgdefs.message_class(type_name)
    text = msgdefs.definition(type_name)
    assert text.count('MSG: ') == len(set(text.split('MSG: ')[1:]))   # each dependency once
    msg = cls()
    if type_name.startswith('eha_msgs'):
        fill(msg, salt=3)
    sink = McapSink(str(tmp_path / 'one.mcap'))
    cid = sink.add_topic('/t', type_name, text, msgdefs.header_first(cls))
    sink.put(cid, 123, serialize(msg))
    assert sink.close() == {'/t': 1}
    (log_time, got), = recording.read(str(tmp_path / 'one.mcap'))['/t']
    assert log_time == 123
    for name in cls.get_fields_and_field_types():
        want, have = getattr(msg, name), getattr(got, name)
        if name == 'header':
            assert (have.stamp.sec, have.stamp.nanosec, have.frame_id) == \
                (want.stamp.sec, want.stamp.nanosec, want.frame_id)
        elif hasattr(want, '__len__') and not isinstance(want, str):
            assert list(have) == list(want), name
        elif not hasattr(want, 'get_fields_and_field_types'):
            assert have == want, name


def test_generated_text_matches_the_msg_file_layout():
    cls = msgdefs.message_class('eha_msgs/msg/ActuatorState')
    text = msgdefs.generated_text(cls)
    assert 'std_msgs/Header header\n' in text and 'float64[2] motor_speed\n' in text
    assert 'bool[2] valve_open\n' in text
    arr = msgdefs.generated_text(msgdefs.message_class('diagnostic_msgs/msg/DiagnosticArray'))
    assert 'diagnostic_msgs/DiagnosticStatus[] status' in arr
    with pytest.raises(ValueError):
        msgdefs.message_class('no_such_pkg/msg/Thing')


def test_sink_publish_time_is_header_stamp_and_columns_by_seq(tmp_path):
    from eha_msgs.msg import ActuatorState, ActuatorCommand
    path = str(tmp_path / 'r.mcap')
    sink = McapSink(path, 'lz4', chunk_size=4096)
    ts = 'eha_msgs/msg/ActuatorState'
    cid = sink.add_topic('/eha/state', ts, msgdefs.definition(ts), True)
    cc = sink.add_topic('/eha/command', 'eha_msgs/msg/ActuatorCommand',
                        msgdefs.definition('eha_msgs/msg/ActuatorCommand'), True)
    for k in [0, 1, 2, 2, 3]:                     # seq 2 twice: a re-sent state
        m = ActuatorState(seq=k, position=k * 1e-3 + (0.5 if k == 2 and
                                                       sink.received[cid] == 3 else 0.0))
        m.header.stamp.sec, m.header.stamp.nanosec = 7, k
        m.motor_speed[1] = -float(k)
        data = serialize(m)
        assert stamp_ns(data) == 7 * 10**9 + k
        sink.put(cid, 1000 + k, data)
    sink.put(cc, 5, serialize(ActuatorCommand(seq=9)))
    assert sink.close() == {'/eha/state': 5, '/eha/command': 1}
    recs = recording.read_records(path)
    assert [r.publish_time - 7 * 10**9 for r in recs['/eha/state']] == [0, 1, 2, 2, 3]
    assert recording.summary(path)['/eha/state'] == {
        'type': ts, 'count': 5, 'offered_qos_profiles': ''}
    rec = recording.read(path)
    last = recording.columns(rec['/eha/state'], ['position', 'motor_speed[1]', 'header.stamp.nanosec'])
    assert list(last['seq']) == [0, 1, 2, 3]
    assert list(last['position']) == [0.0, 1e-3, 2e-3 + 0.5, 3e-3]
    assert list(last['motor_speed[1]']) == [0.0, -1.0, -2.0, -3.0]
    first = recording.columns(rec['/eha/state'], ['position'], keep='first')
    assert first['position'][2] == 2e-3
    from mcap_ros2.reader import read_ros2_messages          # the standard reader agrees
    std = [m.ros_msg.seq for m in read_ros2_messages(path, topics=['/eha/state'])]
    assert std == [0, 1, 2, 2, 3]
    with pytest.raises(recording.RecordingError, match="'nope'"):
        recording.columns(rec['/eha/state'], ['nope'])


def test_unreadable_recordings_are_one_line_errors(tmp_path):
    bad = tmp_path / 'bad.mcap'
    bad.write_bytes(b'\x89MCAP0\r\n' + b'garbage' * 10)
    for path in (str(bad), str(tmp_path / 'missing.mcap')):
        for fn in (recording.read, recording.summary):
            with pytest.raises(UsageError) as err:
                fn(path)
            assert '\n' not in str(err.value) and path in str(err.value)
    with pytest.raises(UsageError, match='cannot write'):
        McapSink(str(bad / 'x.mcap'))


def test_unfinished_recording_reads_up_to_the_cut(tmp_path):
    """A recorder killed with SIGKILL leaves no summary: complete chunks still read back."""
    from eha_msgs.msg import ActuatorState
    path = tmp_path / 'full.mcap'
    sink = McapSink(str(path), chunk_size=2048)
    ts = 'eha_msgs/msg/ActuatorState'
    cid = sink.add_topic('/eha/state', ts, msgdefs.definition(ts), True)
    for k in range(500):
        sink.put(cid, k, serialize(ActuatorState(seq=k, position=float(k))))
    sink.close()
    data = path.read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:len(data) // 2])
    got = [m.seq for _, m in recording.read(str(cut))['/eha/state']]
    assert 50 < len(got) < 500 and got == list(range(len(got)))
    with pytest.raises(UsageError, match='no summary|not a readable'):
        recording.summary(str(cut))


def test_seq_coverage_counts_messages_and_missing_seqs(tmp_path):
    # a long soak's recording is streamed, not loaded: 6 states of seq 10..17 with 13 and 15
    # missing -> 6 messages, 2 gaps (the order in the file does not matter)
    cls = msgdefs.message_class('eha_msgs/msg/ActuatorState')
    name = 'eha_msgs/msg/ActuatorState'
    sink = McapSink(str(tmp_path / 's.mcap'))
    cid = sink.add_topic('/eha/state', name, msgdefs.definition(name), msgdefs.header_first(cls))
    for t, seq in enumerate((10, 11, 12, 14, 17, 16)):
        msg = cls()
        msg.seq = seq
        sink.put(cid, t, serialize(msg))
    sink.close()
    assert recording.seq_coverage(str(tmp_path / 's.mcap'), '/eha/state') == (6, 2)
    assert recording.seq_coverage(str(tmp_path / 's.mcap'), '/eha/command') == (0, 0)
