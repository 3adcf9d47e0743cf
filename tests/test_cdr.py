"""core.io.cdr: the live view's CDR encoder writes what serialize_message writes, field for field,
for every eha_msgs type and values across their ranges; padding zeroed; unsupported layouts
refused so the caller falls back."""
import re
import struct

import numpy as np
import pytest

from eha_ros.core.io import cdr

TYPES = ['ActuatorCommand', 'ActuatorState', 'ChannelSelect', 'ExternalLoad', 'PlantTruth',
         'PositionEstimate', 'PositionReference', 'RedundancyStatus']
_LIMITS = {'uint8': (0, 255), 'uint32': (0, 2**32 - 1), 'uint64': (0, 2**64 - 1)}


def _random(cls, rng, text_len):
    """A message with every field set: extremes of the integer ranges, signed doubles,
    alternating bools, strings of ``text_len`` characters (non-ASCII included)."""
    m = cls()
    m.header.stamp.sec, m.header.stamp.nanosec = int(rng.integers(0, 2**31)), 999_999_999
    m.header.frame_id = 'é' * text_len
    for name, t in cls.get_fields_and_field_types().items():
        base, _, n = t.partition('[')
        if base == 'double':
            setattr(m, name, rng.normal(size=int(n[:-1])) * 1e5 if n else float(rng.normal()))
        elif base == 'boolean':
            setattr(m, name, [bool(i % 2) for i in range(int(n[:-1]))] if n else True)
        elif base in _LIMITS:
            setattr(m, name, _LIMITS[base][int(rng.integers(0, 2))])
        elif base == 'string':
            setattr(m, name, 'x' * (text_len + 3))
    return m


@pytest.mark.parametrize('name', TYPES)
@pytest.mark.parametrize('text_len', [0, 1, 2, 3, 4, 7])
def test_same_message_as_serialize_message(name, text_len):
    """Decoded by rclpy, the bytes are the message; same length; non-padding bytes equal
    (serialize_message's own padding is whatever its buffer held)."""
    from rclpy.serialization import deserialize_message, serialize_message
    import eha_msgs.msg as msgs
    cls = getattr(msgs, name)
    encode = cdr.encoder(cls)
    rng = np.random.default_rng(text_len)
    for _ in range(5):
        m = _random(cls, rng, text_len)
        ours, theirs = encode(m), serialize_message(m)
        assert deserialize_message(ours, cls) == m
        assert len(ours) == len(theirs)
        strings = [m.header.frame_id] + [getattr(m, f) for f, t in
                                         cls.get_fields_and_field_types().items()
                                         if t == 'string']
        pad = _padding(cdr.layout(cdr.fields(cls), tuple(len(x.encode()) for x in strings)))
        assert ours[:4] == cdr.ENCAPSULATION and pad
        assert all(ours[i] == 0 for i in pad)
        assert bytes(b for i, b in enumerate(ours) if i not in pad) == \
            bytes(b for i, b in enumerate(theirs) if i not in pad)


def _padding(st: struct.Struct) -> set[int]:
    """Byte offsets of the 'x' pads of a little-endian struct format."""
    out, pos = set(), 0
    for count, code in re.findall(r'(\d*)([a-zA-Z?])', st.format.lstrip('<')):
        n = int(count or 1)
        size = n if code in 'sx' else struct.calcsize('<' + code) * n
        if code == 'x':
            out.update(range(pos, pos + n))
        pos += size
    assert pos == st.size
    return out


def test_a_wrong_value_is_an_error_not_wrong_bytes():
    from eha_msgs.msg import ActuatorState
    m = ActuatorState()          # the setter checks the range: set the slot past it
    encode = cdr.encoder(ActuatorState)
    object.__setattr__(m, '_active_channel', 300)
    with pytest.raises(struct.error):
        encode(m)


def test_sequences_are_refused():
    from diagnostic_msgs.msg import DiagnosticArray
    with pytest.raises(cdr.Unsupported, match='sequence'):
        cdr.encoder(DiagnosticArray)
