"""Command-line guard: user mistakes end in one line on stderr and a non-zero exit."""
from __future__ import annotations

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
