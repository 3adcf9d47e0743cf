"""scripts/identify's fitting side (issue 43): recordings of the four experiments in, the
identified plant out (identified.yaml, identification.json, report.md with its figures).

Every check of the recordings runs before anything is written (dataset.load_all: one line
naming the file, core.config.cli.UsageError); the fits then cannot fail on user input.
"""
from __future__ import annotations

import os
import time

from .fit import MAX_CORRELATION, REL_HALF_WIDTH, Estimate

BETA_NOTE = ('not determined by the data: the pressure dynamics of eq. 3.20-3.21 ring at the '
             'hydraulic resonance (about 760 Hz on the nominal plant), above the 500 Hz Nyquist '
             'frequency of 1 kHz samples, and the experiments never let bulk compliance show '
             'apart from leakage and the loop')
YAML_KEYS = ('friction.F_c', 'friction.F_s', 'friction.v_s', 'friction.mu', 'drive.Kp_w',
             'drive.Ki_w', 'drive.delay', 'motor.k_T', 'pump.C_p', 'cylinder.C_c', 'pump.C_r')


def nominal_plant(config_dir: str | None):
    """The plant_sim node's plant as config/ gives it (PlantParams) and its parameter dict."""
    from ..hardware.sim_params import SCHEMA
    from ..plant.parameters import PlantParams
    from ..sim.batch import node_params
    values = node_params('plant_sim', SCHEMA, config_dir)
    return PlantParams.from_dict(values), values


def changed_keys(params: dict, values: dict, friction_curve: dict | None = None) -> dict:
    """plant.* overrides of the identified parameters (the C_p : C_c : C_r split scaled with
    C_eq when C_eq is identified), kept only if the plant schema accepts them together.

    Eq. 3.33's four parameters go in as one curve, ``friction_curve`` (name -> fitted value,
    or None: all nominal): they trade off against each other, and a mix of fitted and nominal
    ones is a curve the data never showed (F_s and v_s fitted beside a nominal F_c and mu made
    one plant's validation loop stick and slip, 8.4 mm RMSE)."""
    from ..config.params import ParamError
    from ..plant.parameters import PlantParams
    out = {}
    for key in YAML_KEYS:
        e = params.get(key)
        split = key in ('pump.C_p', 'cylinder.C_c', 'pump.C_r') and params['C_eq'].identified
        if e is not None and not key.startswith('friction.') and (e.identified or split):
            out['plant.' + key] = float(e.value)       # drive.delay: whole ticks already
    curve = {f'plant.friction.{n}': float(v) for n, v in (friction_curve or {}).items()}
    try:
        PlantParams.from_dict({**values, **out, **curve})      # F_s >= F_c (eq. 3.33) et al.
        out.update(curve)
    except ParamError:
        pass
    return out


def fit_recordings(paths: list[str], out_dir: str, config_dir: str | None = None,
                   log=print) -> dict:
    """Fit the plant to the recordings of the drive, friction, leakage and validation
    experiments (one each, any order); write identified.yaml, identification.json, report.md
    and its PNGs into out_dir; return the identification.json content."""
    from . import dataset, drive, friction, leakage, report, validate
    t_all = time.perf_counter()
    p, values = nominal_plant(config_dir)
    recs = dataset.load_all(list(paths), p.Ts, log)
    wall = {'read_s': time.perf_counter() - t_all}
    t0 = time.perf_counter()
    d = drive.identify(recs['drive'], p, log)
    wall['drive_s'] = time.perf_counter() - t0
    t0 = time.perf_counter()
    f = friction.identify(recs['friction'], p, log)
    wall['friction_s'] = time.perf_counter() - t0
    t0 = time.perf_counter()
    k = leakage.identify(recs['leakage'], p, log)
    wall['leakage_s'] = time.perf_counter() - t0
    params: dict[str, Estimate] = {}
    for part in (f, d, k):
        params.update(part['estimates'])
    loaded = params.pop('C_loaded', None)
    params['fluid.beta'] = Estimate(p.beta, None, None, p.beta, False, BETA_NOTE)
    wall['fits_s'] = wall['drive_s'] + wall['friction_s'] + wall['leakage_s']
    curve = f['values'] if f['fit'] is not None and not f['fit'].at_bound and any(
        e.identified for e in f['estimates'].values()) else None
    overrides = changed_keys(params, values, curve)
    t0 = time.perf_counter()
    v = validate.validate(recs['validation'], overrides, config_dir, log)
    wall['validation_s'] = time.perf_counter() - t0
    result = {
        'parameters': {name: e.as_dict() for name, e in sorted(params.items())},
        'validation': {key: v[key] for key in ('seeds', 'position_rmse_m',
                                               'motor_speed_rmse_rad_s')},
        'drive_sweep': {'motor_speed_rmse_rad_s': d['speed_rmse_rad_s'],
                        'motor_speed_max_error_rad_s': d['speed_max_error_rad_s'],
                        'delay_cost': {str(t): c for t, c in sorted(d['delay_cost'].items())}},
        'friction': {'force_rmse_n': f['force_rmse_n']},
        'leakage': {'loaded_leakage': loaded.as_dict() if loaded else None,
                    'levels': k['levels']},
        'fits': {name: part['fit'].summary() if part['fit'] is not None else None
                 for name, part in (('drive', d), ('friction', f), ('leakage', k))},
        'identified_yaml': overrides,
        'criteria': {'interval': '95 %, cluster-robust (core/ident/fit.py)',
                     'identified_max_relative_half_width': REL_HALF_WIDTH,
                     'identified_max_correlation': MAX_CORRELATION},
        'recordings': {exp: {'path': os.path.abspath(r.path), 'plant_side': r.plant_side,
                             'duration_s': r.n * r.Ts, 'params': r.params}
                       for exp, r in recs.items()},
    }
    os.makedirs(out_dir, exist_ok=True)
    write_params_file(os.path.join(out_dir, 'identified.yaml'), overrides)
    t0 = time.perf_counter()
    report.write(out_dir, result, d, f, k, v, p)
    wall['report_s'] = time.perf_counter() - t0
    wall['total_s'] = time.perf_counter() - t_all
    result['wall_time'] = wall
    from ..io.report import write_json
    write_json(os.path.join(out_dir, 'identification.json'), result)
    log(f'identify: fits {wall["fits_s"]:.1f} s, total {wall["total_s"]:.1f} s; wrote '
        f'{out_dir}/identified.yaml, identification.json, report.md')
    return result


def write_params_file(path: str, overrides: dict) -> None:
    """A ROS params file for plant_sim with only ``overrides`` (plant.* keys) under /**."""
    tree: dict = {}
    for key, value in sorted(overrides.items()):
        *groups, leaf = key.split('.')
        node = tree
        for g in groups:
            node = node.setdefault(g, {})
        node[leaf] = value
    lines = ['# Identified plant parameters (scripts/identify): only the changed keys; give it',
             '# to plant_sim as one more --params-file after config/plant.yaml.',
             '/**:', '  ros__parameters:']

    def emit(node, depth):
        for name, value in node.items():
            if isinstance(value, dict):
                lines.append('  ' * depth + f'{name}:')
                emit(value, depth + 1)
            else:
                text = repr(float(value))
                if 'e' in text and '.' not in text:     # YAML 1.1 floats need a dot
                    text = text.replace('e', '.0e')
                lines.append('  ' * depth + f'{name}: {text}')

    emit(tree, 2)
    tmp = path + '.tmp'
    with open(tmp, 'w') as fh:
        fh.write('\n'.join(lines) + '\n')
    os.replace(tmp, path)
