"""Command-line guard: user mistakes end in one line on stderr and a non-zero exit."""
from __future__ import annotations

import math
import signal
import sys
from typing import Callable

from .params import ParamError


class UsageError(Exception):
    """A bad argument or input from the user; ``str(err)`` is one line."""


EXIT_CONFIG = 2


def guarded(prog: str, main: Callable[[], int | None]) -> int:
    """Run ``main``; turn configuration/usage errors into ``prog: error: ...`` and exit 2."""
    try:
        code = main()
    except (ParamError, UsageError) as err:
        print(f'{prog}: error: {err}', file=sys.stderr, flush=True)
        return EXIT_CONFIG
    except KeyboardInterrupt:
        return 130
    return int(code or 0)


def require_seconds(option: str, value: float, least: float = 0.0, strict: bool = True) -> None:
    """UsageError (one line) unless ``value`` is a finite number of seconds above ``least``
    (at least ``least`` with strict=False): nan and inf included."""
    if not (math.isfinite(value) and (value > least if strict else value >= least)):
        raise UsageError(f'{option} {value:g}: expected a finite number of seconds '
                         f'{">" if strict else ">="} {least:g}')


_STOPPING = []          # non-empty once the program's clean stop has begun


def stopping() -> None:
    """The clean stop has begun (whatever ended the run): from now on a signal is reported,
    it no longer interrupts (a KeyboardInterrupt inside the stop would cut it short)."""
    _STOPPING.append(True)


def interrupt_on_signals() -> list:
    """SIGTERM, SIGHUP and SIGINT end a run as Ctrl-C does: KeyboardInterrupt in the main
    thread, once. The clean stop that follows (nodes stopped in order, the run's JSON and
    recording finished) is not cut short by a second signal; the children are bounded by
    Stack.stop's timeout and SIGKILL. Returns the list the first signal's number goes to."""
    fired = []

    def handler(signum, frame):
        if not fired and not _STOPPING:
            fired.append(signum)
            raise KeyboardInterrupt
        print(f'{signal.Signals(signum).name}: already stopping', file=sys.stderr, flush=True)

    for sig in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT):
        signal.signal(sig, handler)
    return fired
