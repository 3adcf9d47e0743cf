"""Read an MCAP recording of the stack (written by the recorder node) back into Python.

No rclpy import: messages are decoded from the ros2msg schemas stored in the file
(mcap_ros2), so a recording reads back on any machine with ``mcap-ros2-support``::

    rec = read('out/run.mcap')                       # {topic: [(log_time_ns, msg), ...]}
    cols = columns(rec['/eha/state'], ['position', 'motor_speed[0]'])
    cols['seq'], cols['position']                    # numpy arrays, sorted by seq

Messages of a topic come in the order the recorder received them (file order). A file whose
recorder was killed (no summary) still reads, up to its last complete chunk.
"""
from __future__ import annotations

import os
import re
from collections import defaultdict
from typing import Any, Iterable, NamedTuple, Sequence

import numpy as np

from ..config.cli import UsageError


class RecordingError(UsageError):
    """An unreadable or malformed recording; ``str(err)`` is one line."""


def _factories():
    from mcap_ros2.decoder import DecoderFactory
    return (DecoderFactory(),)


def _open(path: str):
    try:
        return open(path, 'rb')
    except OSError as err:
        raise RecordingError(f'{path}: cannot read recording: {err.strerror}') from None


def _bad(path: str, err: Exception) -> RecordingError:
    return RecordingError(f'{path}: not a readable MCAP recording: '
                          f'{type(err).__name__}: {err}'.splitlines()[0])


def _iterate(path: str, topics: Iterable[str] | None):
    """(channel, message, decoded) in file order. A finished file is read through its index;
    an unfinished one (recorder killed) sequentially, up to its last complete record."""
    from mcap.reader import NonSeekingReader, SeekingReader
    with _open(path) as fh:
        try:
            reader = SeekingReader(fh, decoder_factories=_factories())
            finished = reader.get_summary() is not None
        except Exception:
            finished = False
        if not finished:
            fh.seek(0)
            reader = NonSeekingReader(fh, decoder_factories=_factories())
        n = 0
        try:
            for _, channel, message, msg in reader.iter_decoded_messages(
                    topics=topics, log_time_order=False):
                n += 1
                yield channel, message, msg
        except Exception as err:     # mcap raises many kinds (McapError, EndOfFile, ...)
            if finished or n == 0:
                raise _bad(path, err) from None


def read(path: str, topics: Iterable[str] | None = None) -> dict[str, list[tuple[int, Any]]]:
    """Decoded messages per topic: {topic: [(log_time_ns, msg), ...]} in receive order."""
    out: dict[str, list] = defaultdict(list)
    for channel, message, msg in _iterate(path, topics):
        out[channel.topic].append((message.log_time, msg))
    return dict(out)


def seq_coverage(path: str, topic: str) -> tuple[int, int]:
    """(messages, seq gaps) of a topic whose messages carry ``seq``, streamed (a long recording
    is never held in memory): gaps = seq values missing between the first and the last."""
    n, lo, hi = 0, None, None
    for _, _, msg in _iterate(path, [topic]):
        n += 1
        lo = msg.seq if lo is None else min(lo, msg.seq)
        hi = msg.seq if hi is None else max(hi, msg.seq)
    return n, (hi - lo + 1 - n) if n else 0


class Record(NamedTuple):
    """One recorded message: times in ns, the decoded message and its CDR bytes."""
    log_time: int
    publish_time: int
    msg: Any
    data: bytes


def read_records(path: str, topics: Iterable[str] | None = None) -> dict[str, list[Record]]:
    """Everything per topic, decoded and raw (for bit-exact comparisons), in receive order."""
    out: dict[str, list] = defaultdict(list)
    for channel, message, msg in _iterate(path, topics):
        out[channel.topic].append(Record(message.log_time, message.publish_time, msg,
                                         bytes(message.data)))
    return dict(out)


def finished(path: str) -> bool:
    """The recording has its summary (its recorder closed it)."""
    try:
        summary(path)
    except RecordingError:
        return False
    return True


def recover(path: str) -> dict:
    """Rewrite an unfinished recording (its recorder killed: no summary, maybe a cut last
    chunk) as a finished one that any MCAP reader opens, with every message up to the last
    complete chunk. Returns {'messages': n, 'topics': n}; a finished file is left as it is."""
    try:
        topics = summary(path)               # finished: nothing to do
        return {'messages': sum(v['count'] for v in topics.values()), 'topics': len(topics)}
    except RecordingError:
        pass
    tmp = path + '.recovering'
    try:
        n, topics = _rewrite(path, tmp)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
    os.replace(tmp, path)
    return {'messages': n, 'topics': topics}


def _rewrite(path: str, tmp: str) -> tuple[int, int]:
    """Copy the complete records of ``path`` into a finished MCAP file ``tmp``."""
    from mcap.records import Channel, Message, Schema
    from mcap.writer import CompressionType, Writer
    schemas, channels, n = {}, {}, 0
    with _open(path) as src, open(tmp, 'wb') as dst:
        writer = Writer(dst, compression=CompressionType.ZSTD)
        writer.start(profile='ros2', library='eha_ros recording.recover')
        for rec in _complete_records(src):
            if isinstance(rec, Schema):
                schemas[rec.id] = writer.register_schema(rec.name, rec.encoding, rec.data)
            elif isinstance(rec, Channel):
                channels[rec.id] = writer.register_channel(
                    rec.topic, rec.message_encoding, schemas.get(rec.schema_id, 0),
                    dict(rec.metadata))
            elif isinstance(rec, Message) and rec.channel_id in channels:
                writer.add_message(channels[rec.channel_id], rec.log_time, rec.data,
                                   rec.publish_time, rec.sequence)
                n += 1
        writer.finish()
    return n, len(channels)


def _complete_records(src):
    """The file's records (chunks opened) up to the first one cut short."""
    from mcap.stream_reader import StreamReader
    records = iter(StreamReader(src).records)
    while True:
        try:
            rec = next(records)
        except Exception:            # StopIteration at the end; at a cut, mcap raises many
            return                   # kinds (EndOfFile, CRC, ...)
        yield rec


def summary(path: str) -> dict:
    """Topics with their type and message count from the file's summary section."""
    from mcap.reader import SeekingReader
    with _open(path) as fh:
        try:
            s = SeekingReader(fh).get_summary()
        except Exception as err:
            raise _bad(path, err) from None
    if s is None or s.statistics is None:
        raise RecordingError(f'{path}: recording has no summary (not finished properly?)')
    counts = s.statistics.channel_message_counts
    return {ch.topic: {'type': s.schemas[ch.schema_id].name if ch.schema_id in s.schemas else '',
                       'count': int(counts.get(cid, 0)),
                       'offered_qos_profiles': ch.metadata.get('offered_qos_profiles', '')}
            for cid, ch in s.channels.items()}


_PART = re.compile(r'([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?$')


def field(msg: Any, path: str) -> Any:
    """A (nested) field by dotted path with indices: 'header.stamp.sec', 'motor_speed[1]'."""
    value = msg
    for part in path.split('.'):
        m = _PART.match(part)
        if m is None:
            raise RecordingError(f'field {path!r}: expected name, name.sub or name[index]')
        try:
            value = getattr(value, m.group(1))
            if m.group(2) is not None:
                value = value[int(m.group(2))]
        except (AttributeError, IndexError, TypeError):
            raise RecordingError(f'field {path!r}: not in message {type(msg).__name__}') \
                from None
    return value


def columns(records: Sequence[tuple[int, Any]], fields: Sequence[str], key: str = 'seq',
            keep: str = 'last') -> dict[str, np.ndarray]:
    """numpy columns of chosen fields keyed by ``key`` (sorted, unique; duplicates of a key,
    e.g. a lock-step re-publish, keep the 'last' or 'first' one) plus 'log_time' in seconds."""
    if keep not in ('first', 'last'):
        raise RecordingError(f"keep = {keep!r}: expected 'first' or 'last'")
    chosen: dict = {}
    for log_time, msg in records:
        k = field(msg, key)
        if keep == 'last' or k not in chosen:
            chosen[k] = (log_time, msg)
    keys = sorted(chosen)
    out = {key: np.array(keys), 'log_time': np.array([chosen[k][0] * 1e-9 for k in keys])}
    for name in fields:
        out[name] = np.array([field(chosen[k][1], name) for k in keys])
    return out
