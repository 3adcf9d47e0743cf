"""Parameters of the recorder node (recorder.*): what to record, where, how deep the queues."""
from __future__ import annotations

from ..config.params import Param, Schema

SCHEMA = Schema('recorder', [
    Param('recorder.output', 'str', '', '',
          doc='MCAP file to write; empty = out/recording_<time>.mcap'),
    Param('recorder.namespace', 'str', '', '/eha',
          doc='every topic under this namespace is recorded'),
    Param('recorder.diagnostics', 'bool', '', True, doc='also record /diagnostics'),
    Param('recorder.extra_topics', 'str[]', '', [''], min_len=1,
          doc='further topics to record by exact name (e.g. /clock); empty string = none'),
    Param('recorder.discovery_period', 'float', 's', 0.2, 0.01, 10.0,
          doc='look for new topics this often (wall time)'),
    Param('recorder.depth', 'int', '', 1000, 1, 100000,
          doc='subscription queue depth (reliable topics): 1 s of a 1 kHz stream'),
    Param('recorder.compression', 'str', '', 'zstd', choices=('zstd', 'lz4', 'none'),
          doc='MCAP chunk compression'),
    Param('recorder.chunk_size', 'int', 'B', 1 << 18, 1024, 1 << 30,
          doc='MCAP chunk size before compression: the most a killed recorder loses (the '
              'chunk being filled; 256 KiB: about 0.3 s of the stack\'s streams)'),
    Param('recorder.diagnostics_period', 'float', 's', 1.0, 0.05, 60.0,
          doc='/diagnostics period'),
])
