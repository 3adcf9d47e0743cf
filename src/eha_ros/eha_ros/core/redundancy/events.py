"""Switch-event log: one record per transition of the switch manager (time, from, to, reason,
health figures), kept in memory and appended as JSON lines to a file."""
from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field


@dataclass
class SwitchEvent:
    t: float                  # plant time of the event, seq * Ts [s]
    seq: int                  # plant tick [-]
    kind: str                 # switch_start | switch_done | degraded | restored | safe | refused
    #                           | sensor_fault (the shared pressure sensors, not a couple)
    from_state: str
    to_state: str
    from_channel: int
    to_channel: int
    reason: str
    commanded: bool = False
    switch_count: int = 0
    health: dict = field(default_factory=dict)    # 'A'/'B' -> monitor -> {value, healthy}

    def to_dict(self) -> dict:
        return asdict(self)

    def line(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True, allow_nan=True)


class EventLog:
    """Appends events to ``<folder>/switch_events.jsonl``; each line is one ``os.write`` on an
    O_APPEND descriptor, so a reader never sees half a record and two writers do not mix."""

    FILE = 'switch_events.jsonl'

    def __init__(self, folder: str):
        self.path = os.path.join(folder, self.FILE) if folder else ''
        if self.path:
            os.makedirs(folder, exist_ok=True)

    def append(self, event: SwitchEvent) -> None:
        if not self.path:
            return
        data = (event.line() + '\n').encode()
        fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, data)
        finally:
            os.close(fd)


def read_log(path: str) -> list[dict]:
    """The records of a switch-event log file."""
    with open(path, encoding='utf-8') as fh:
        return [json.loads(line) for line in fh if line.strip()]
