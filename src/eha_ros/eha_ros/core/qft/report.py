"""Controller YAML (contract format) and the markdown/JSON design report."""
from __future__ import annotations

import json

import numpy as np
import yaml

from ..config.params import ParamError
from ..controller.lti import Zpk, from_num_den

NAMES = ('position_controller', 'prefilter', 'velocity_controller')


def write_controller_yaml(path, Gv: Zpk, G: Zpk, F: Zpk, header: str, aw_poles=None):
    """controller: ros__parameters: {position_controller, prefilter, velocity_controller,
    antiwindup} (antiwindup: the poles of G while clamped, core.controller.antiwindup)."""
    params = {}
    for name, tf in zip(NAMES, (G, F, Gv)):
        num, den = tf.num_den()
        params[name] = {'num': num, 'den': den}
    if aw_poles is not None:
        p = np.asarray(aw_poles, complex)
        params['antiwindup'] = {'poles_real': [float(v) for v in p.real],
                                'poles_imag': [float(v) for v in p.imag]}
    body = yaml.safe_dump({'controller': {'ros__parameters': params}}, sort_keys=False,
                          default_flow_style=None, width=200)
    lines = ['# ' + ln if ln else '#' for ln in header.strip().splitlines()]
    lines += ['# units: position_controller G(s): m of error -> rad/s motor-speed reference;',
              '#        velocity_controller G_v(s): rad/s of speed error -> A current reference',
              '#        (eq. 4.65 incl. 1/k_T); prefilter F(s): m -> m. Continuous time,',
              '#        coefficients in descending powers of s. antiwindup: poles (rad/s) of G',
              '#        while the speed clamp is active, placed at exp(s Ts) by the observer gain.']
    with open(path, 'w', encoding='utf-8') as fh:
        fh.write('\n'.join(lines) + '\n' + body)


def read_controller_yaml(path):
    """(G_v, G, F) as Zpk from a controller YAML."""
    try:
        with open(path, encoding='utf-8') as fh:
            doc = yaml.safe_load(fh)
        p = doc['controller']['ros__parameters']
        G = from_num_den(p['position_controller']['num'], p['position_controller']['den'])
        F = from_num_den(p['prefilter']['num'], p['prefilter']['den'])
        Gv = from_num_den(p['velocity_controller']['num'], p['velocity_controller']['den'])
    except (OSError, KeyError, TypeError, ValueError, yaml.YAMLError) as err:
        raise ParamError(f'{path}: cannot read controller YAML: {err}') from None
    return Gv, G, F


def read_antiwindup_poles(path):
    """The anti-windup poles of a controller YAML (complex array), None if it has none."""
    from ..controller.antiwindup import poles_from_params
    try:
        with open(path, encoding='utf-8') as fh:
            aw = yaml.safe_load(fh)['controller']['ros__parameters'].get('antiwindup')
        return None if aw is None else poles_from_params(aw['poles_real'], aw['poles_imag'])
    except (OSError, KeyError, TypeError, ValueError, yaml.YAMLError) as err:
        raise ParamError(f'{path}: cannot read the anti-windup poles: {err}') from None


def _fmt(v):
    if isinstance(v, bool):
        return 'PASS' if v else 'FAIL'
    if isinstance(v, float):
        return f'{v:.4g}'
    return str(v)


ROWS = [
    ('vel_max_real_eig', 'velocity loop: max Re(eig) over family (1/s)', 'vel_stable'),
    ('vel_max_T_db', 'velocity loop: worst max|T_v| (dB) vs W_s^v', 'vel_Ws'),
    ('vel_Ws_db', '  W_s^v (dB)', None),
    ('vel_sens_worst_db', 'velocity loop: worst |S_v|/|S^v spec| (dB), w <= max design w', 'vel_sensitivity'),
    ('vel_gm_min_db', 'velocity loop: min GM (dB)', None),
    ('vel_pm_min_deg', 'velocity loop: min PM (deg)', None),
    ('vel_bound_violation_db', 'velocity loop: worst bound violation at design w (dB)', 'vel_bounds'),
    ('pos_max_real_eig', 'position loop: max Re(eig) over family (1/s)', 'pos_stable'),
    ('pos_max_T_db', 'position loop: worst max|T| (dB) vs W_s', 'pos_Ws'),
    ('pos_Ws_db', '  W_s (dB)', None),
    ('pos_sens_worst_db', 'position loop: worst |S|/|S spec| (dB) up to 7 Hz', 'pos_sensitivity'),
    ('pos_stiff_worst_db', 'position loop: worst |P_d S|/|M| (dB) up to 7 Hz', 'pos_stiffness'),
    ('pos_stiffness_min_N_per_mm', '  min dynamic stiffness up to 7 Hz (N/mm)', None),
    ('track_over_up_db', 'tracking: worst |F T| above T_up (dB)', 'tracking'),
    ('track_under_low_db', 'tracking: worst |F T| below T_low (dB)', None),
    ('pos_gm_min_db', 'position loop: min GM (dB)', None),
    ('pos_pm_min_deg', 'position loop: min PM (deg)', None),
    ('bw_min_hz', 'closed-loop -3 dB bandwidth of F T, min over family (Hz)', None),
    ('bw_max_hz', 'closed-loop -3 dB bandwidth of F T, max over family (Hz)', None),
    ('bw_nominal_hz', 'closed-loop -3 dB bandwidth, nominal plant (Hz)', 'bandwidth_nominal'),
    ('pos_bound_violation_db', 'position loop: worst bound violation at design w (dB)', 'pos_bounds'),
    ('loop_delay_ms', 'position-loop delay T_d in all of the above (ms)', None),
    ('dig_Ts_ms', 'digital: Ts (ms); ZOH plant, Tustin G and F', None),
    ('dig_delay_samples', 'digital: delay shift states (samples)', None),
    ('dig_max_abs_eig', 'digital: max |eig| of the closed loop over family', 'dig_stable'),
    ('nom_cont_max_T_db', 'nominal max|T| (dB), continuous with delay', None),
    ('nom_dig_max_T_db', 'nominal max|T| (dB), discrete', 'dig_agree'),
    ('nom_cont_gm_db', 'nominal GM (dB), continuous with delay', None),
    ('nom_dig_gm_db', 'nominal GM (dB), discrete', None),
    ('nom_cont_pm_deg', 'nominal PM (deg), continuous with delay', None),
    ('nom_dig_pm_deg', 'nominal PM (deg), discrete', None),
    ('step_overshoot_pct', 'digital step of F T, nominal: overshoot (%)', 'step_nominal'),
    ('step_settling_s', 'digital step of F T, nominal: 2 % settling time (s)', None),
    ('step_overshoot_worst_pct', 'digital step of F T, worst plant: overshoot (%)', 'step_family'),
    ('step_settling_worst_s', 'digital step of F T, worst plant: 2 % settling time (s)', None),
    ('aw_circle_min_re', 'anti-windup: min Re H over family and grid (circle criterion, >= 0)',
     'aw_circle'),
    ('aw_circle_worst_w', '  at w (rad/s)', None),
]


def markdown(results: dict, extra: str = '') -> str:
    """Side-by-side table of the analyses in results (name -> analyse() dict)."""
    names = list(results)
    out = ['| figure | ' + ' | '.join(names) + ' |', '|---|' + '---|' * len(names)]
    for key, label, verdict in ROWS:
        cells = []
        for n in names:
            r = results[n]
            if key not in r:
                cells.append('-')
                continue
            v = _fmt(r[key])
            if verdict and verdict in r['pass']:
                v += ' ' + _fmt(r['pass'][verdict])
            cells.append(v)
        out.append(f'| {label} | ' + ' | '.join(cells) + ' |')
    out.append('| **all checks** | ' + ' | '.join(_fmt(results[n]['all_pass']) for n in names) + ' |')
    return '\n'.join(out) + '\n' + extra


def write_json(path, obj):
    def conv(o):
        if isinstance(o, (np.floating, np.integer)):
            return o.item()
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, np.bool_):
            return bool(o)
        raise TypeError(type(o))
    with open(path, 'w', encoding='utf-8') as fh:
        json.dump(obj, fh, indent=2, default=conv)
