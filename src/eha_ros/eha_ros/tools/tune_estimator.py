"""tune_estimator: derive the estimator's adaptive-state variances and projection ranges from
the Table 4.5 family and the robustness box (core.estimator.tuning), print them, and with
--write put them into their one home: the TUNED table of core/estimator/params.py, which the
estimator reads (core.estimator.params.adaptive_prior; they are no parameters: they follow from
the family, so a changed family is taken in by running this again). Also printed: the sensor
bands the estimator derives at run time from plant.sensors (core.estimator.sensor_band).

It reads no noise seed. A tuning is checked with campaigns on the tuning seeds 1-5
(scripts/campaign ... --seeds tuning); the figures of record come from the held-out seeds
101-105, which no tuning reads (docs/measurements.md, "Tuning seeds and figures of record")."""
from __future__ import annotations

import argparse
import os
import sys

from ..core.config.cli import guarded
from ..core.estimator import sensor_band, tuning
from ..core.estimator.params import ESTIMATOR
from ..core.config.params import default_config_dir, load
from ..core.plant.parameters import PLANT_SCHEMA
from ..core.qft.spec import load_spec

PROG = 'tune_estimator'
PARAMS_PY = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                         'core', 'estimator', 'params.py')
BEGIN, END = '# BEGIN tune_estimator', '# END tune_estimator'


def parse(argv):
    head, seeds = (part.replace('\n', ' ') for part in __doc__.split('\n\n'))
    ap = argparse.ArgumentParser(prog=PROG, description=head, epilog=seeds)
    cfg = default_config_dir()
    ap.add_argument('--spec', default=os.path.join(cfg, 'qft_spec.yaml'),
                    help='family ranges (family.*_range), default config/qft_spec.yaml')
    ap.add_argument('--plant', default=os.path.join(cfg, 'plant.yaml'),
                    help='nominal plant: its leakage and sensor model (plant.sensors.*)')
    ap.add_argument('--out', default=PARAMS_PY,
                    help='Python file with the TUNED table (default: core/estimator/params.py)')
    ap.add_argument('--write', action='store_true',
                    help='rewrite the TUNED table of --out in place')
    ap.add_argument('--margin', type=float, default=tuning.Inputs(family={}).margin,
                    help='projection range widening, a fraction of the span on each side '
                         '(default %(default)s)')
    return ap.parse_args(argv)


def fmt(v) -> str:
    if isinstance(v, list):
        return '[' + ', '.join(fmt(x) for x in v) + ']'
    return f'{v:.4g}' if abs(v) >= 1e-3 or v == 0 else f'{v:.4e}'


def number(v) -> str:
    """Python text of fmt(v) read back as a float (4 significant digits, a float even for 0)."""
    if isinstance(v, list):
        return '[' + ', '.join(number(x) for x in v) + ']'
    return repr(float(fmt(v)))


def table(values: dict) -> list[str]:
    """The lines of the TUNED table (between the BEGIN and END markers)."""
    return ['TUNED = {'] + [f'    {k!r}: {number(v)},' for k, v in values.items()] + ['}']


def write(path: str, values: dict) -> None:
    """Replace the TUNED table between the markers of ``path`` (the rest kept)."""
    with open(path, encoding='utf-8') as fh:
        lines = fh.read().split('\n')
    try:
        i, j = lines.index(BEGIN), lines.index(END)
    except ValueError:
        raise KeyError(f'{path}: no {BEGIN!r} ... {END!r} block') from None
    lines[i + 1:j] = table(values)
    with open(path, 'w', encoding='utf-8') as fh:
        fh.write('\n'.join(lines))


def main(argv=None) -> int:
    a = parse(sys.argv[1:] if argv is None else argv)
    spec = load_spec(a.spec)
    pp = load(PLANT_SCHEMA, [a.plant])
    fam = {n: tuple(spec[f'family.{n}_range']) for n in ('C_eq', 'D_p', 'beta', 'k_T', 'k_E')}
    inp = tuning.Inputs(family=fam, margin=a.margin,
                        C_x=pp['plant.pump.C_p'] + pp['plant.cylinder.C_c'],
                        C_r=pp['plant.pump.C_r'])
    res = tuning.derive(inp)
    for line in res['notes']:
        print(line)
    b = sensor_band.from_params({**pp, 'estimator.monitor.lowpass': ESTIMATOR.defaults()[
        'estimator.monitor.lowpass']})
    print(f'sensor bands (at run time from plant.sensors, x{sensor_band.NOISE_SCALE:g} noise, '
          f'{b.z:.2f} sigma): offset bound {b.offset_bound * 1e6:.0f} um, DISAGREE band '
          f'{b.band * 1e6:.0f} um, jump step {b.jump_step * 1e6:.0f} um')
    for k, v in res['values'].items():
        print(f'TUNED {k}: {fmt(v)}')
    if a.write:
        write(a.out, res['values'])
        print(f'written: {a.out}')
    return 0


def entry() -> int:
    return guarded(PROG, main)


if __name__ == '__main__':
    sys.exit(entry())
