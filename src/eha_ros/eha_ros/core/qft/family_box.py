"""The random plant family's box: multiplier ranges beyond Table 4.5 (issue 15), read from
config/campaigns/family_random.yaml; used by the campaigns (core.sim.family) and the estimator
tuning (core.estimator.tuning)."""
from __future__ import annotations

import math
import os

import yaml

from ..config.cli import UsageError
from ..config.params import default_config_dir
from .family import NAMES

EXTRA = ('friction', 'noise', 'leak_split')
COLUMNS = NAMES + EXTRA


def load_box(path: str | None = None) -> dict:
    """{column: (lo, hi, log)} of a random-family box YAML (config/campaigns/family_random.yaml)."""
    path = path or os.path.join(default_config_dir(), 'campaigns', 'family_random.yaml')
    try:
        with open(path) as f:
            doc = yaml.safe_load(f)
    except (OSError, yaml.YAMLError) as err:
        raise UsageError(f'{path}: cannot read the family box: {str(err).splitlines()[0]}')
    box = doc.get('family') if isinstance(doc, dict) else None
    if not isinstance(box, dict) or not box:
        raise UsageError(f'{path}: expected a mapping "family:" of multiplier: {{min, max}}')
    out = {}
    for name, b in box.items():
        if name not in COLUMNS:
            raise UsageError(f'{path}: family.{name}: unknown multiplier, expected one of '
                             f'{", ".join(COLUMNS)}')
        try:
            lo, hi, log = float(b['min']), float(b['max']), bool(b.get('log', False))
        except (TypeError, KeyError, ValueError):
            raise UsageError(f'{path}: family.{name}: expected {{min: number, max: number}}, '
                             f'got {b!r}')
        if not (0 < lo <= hi and math.isfinite(hi)):
            raise UsageError(f'{path}: family.{name}: expected 0 < min <= max, got {lo}, {hi}')
        out[name] = (lo, hi, log)
    return out
