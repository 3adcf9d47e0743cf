"""numba's ``cache=True`` keys a function's on-disk cache on its own source file only: a kernel
that calls compiled functions of other files (the closed-loop segment, the plant tick) would
keep stale machine code after one of those files changed. :func:`drop_stale` removes a
module's cache files when a file it depends on is newer; call it at import, before the
module's kernels first run."""
from __future__ import annotations

import glob
import os


def drop_stale(module_file: str, *dep_dirs: str) -> None:
    """Delete ``module_file``'s numba cache (``__pycache__/<stem>.*.nbi|nbc``) if any .py in
    ``dep_dirs`` (folders, relative to the module's) is newer than the oldest cache file."""
    here = os.path.dirname(os.path.abspath(module_file))
    stem = os.path.splitext(os.path.basename(module_file))[0]
    cache = [f for ext in ('nbi', 'nbc')
             for f in glob.glob(os.path.join(here, '__pycache__', f'{stem}.*.{ext}'))]
    if not cache:
        return
    deps = [f for d in dep_dirs or ('.',) for f in glob.glob(os.path.join(here, d, '*.py'))]
    try:
        stale = max(os.path.getmtime(f) for f in deps) > min(os.path.getmtime(f) for f in cache)
    except (OSError, ValueError):
        return
    if stale:
        for f in cache:
            try:
                os.remove(f)
            except OSError:
                pass
