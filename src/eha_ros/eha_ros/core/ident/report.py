"""report.md of an identification with the thesis' pictures (sec. 3.6): the drive sweep
(Fig. 3.36), friction against speed (Fig. 3.42), the leakage test (Fig. 3.44) and the
validation runs (Fig. 3.45); plotting only, the numbers come from the fits."""
from __future__ import annotations

import os

import numpy as np

RPM = 60.0 / (2.0 * np.pi)
UNITS = {'friction.F_c': ('N', 1.0), 'friction.F_s': ('N', 1.0), 'friction.v_s': ('mm/s', 1e3),
         'friction.mu': ('N s/m', 1.0), 'drive.Kp_w': ('Nm s/rad', 1.0),
         'drive.Ki_w': ('Nm/rad', 1.0), 'drive.delay': ('ms', 1e3), 'motor.k_T': ('Nm/A', 1.0),
         'fluid.beta': ('GPa', 1e-9), 'C_eq': ('m^3/(s Pa)', 1.0),
         'pump.C_p': ('m^3/(s Pa)', 1.0), 'cylinder.C_c': ('m^3/(s Pa)', 1.0),
         'pump.C_r': ('m^3/(s Pa)', 1.0)}


def _num(x, scale=1.0) -> str:
    return '-' if x is None else f'{x * scale:.4g}'


def _figure(rows: int = 1, height: float = 3.2):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt.subplots(rows, 1, figsize=(9, height * rows), sharex=rows > 1, squeeze=False)


def drive_png(path: str, d: dict) -> None:
    """Fig. 3.36: measured and simulated motor speed of the sweep."""
    from ..io.report import save_png
    s = d['signals']
    fig, ax = _figure(2)
    ax = ax[:, 0]
    ax[0].plot(s['t'], s['measured'] * RPM, 'k', lw=0.6, label='measured')
    for m, style in (('nominal', 'C1'), ('identified', 'C0')):
        ax[0].plot(s['t'], s[m] * RPM, style, lw=0.6,
                   label=f'{m} model (RMSE {d["speed_rmse_rad_s"][m] * RPM:.1f} rpm)')
    ax[0].set_ylabel('motor speed [rpm]')
    ax[0].legend(loc='upper right', fontsize=8)
    for m, style in (('nominal', 'C1'), ('identified', 'C0')):
        ax[1].plot(s['t'], (s[m] - s['measured']) * RPM, style, lw=0.5, label=m)
    ax[1].set_ylabel('simulated - measured [rpm]')
    ax[1].set_xlabel('time [s]')
    ax[1].legend(loc='upper right', fontsize=8)
    ax[0].set_title('Drive sweep (thesis Fig. 3.36): motor speed')
    save_png(fig, path)


def friction_png(path: str, f: dict, p) -> None:
    """Fig. 3.42: pressure force against piston velocity with the fitted eq. 3.33."""
    from ..io.report import save_png
    from .friction import curve
    fig, ax = _figure(1, 4.5)
    ax = ax[0, 0]
    data = f['data']
    step = max(1, len(data['velocity']) // 4000)
    ax.plot(data['velocity'][::step] * 1e3, data['force'][::step], '.', color='0.7', ms=2,
            label='A_p (p_A - p_B) - m_p a, samples')
    ax.plot(data['bin_velocity'] * 1e3, data['bin_force'], 'ko', ms=3, label='binned means')
    vmax = np.max(np.abs(data['velocity']))
    v = np.linspace(-vmax, vmax, 801)
    c = f['values']
    ax.plot(v * 1e3, curve(v, c['F_c'], c['F_s'], c['v_s'], c['mu']), 'C0',
            label=f'identified (RMSE {f["force_rmse_n"]["identified"]:.0f} N)')
    ax.plot(v * 1e3, curve(v, p.F_c, p.F_s, p.v_s, p.mu), 'C1--',
            label=f'nominal (RMSE {f["force_rmse_n"]["nominal"]:.0f} N)')
    ax.set_xlabel('piston velocity [mm/s]')
    ax.set_ylabel('friction force [N]')
    ax.set_title('Friction (thesis Fig. 3.42), eq. 3.33')
    ax.legend(fontsize=8)
    save_png(fig, path)


def leakage_png(path: str, k: dict, p) -> None:
    """Fig. 3.44: held loads, the motor speed that holds them, the leakage coefficient."""
    from ..io.report import save_png
    s = k['signals']
    fig, ax = _figure(3, 2.6)
    ax = ax[:, 0]
    ax[0].plot(s['t'], s['load'] * 1e-3, 'k', lw=0.8)
    ax[0].set_ylabel('load [kN]')
    ax[1].plot(s['t'], s['speed'] * RPM, 'C0', lw=0.5)
    ax[1].set_ylabel('motor speed [rpm]')
    with np.errstate(divide='ignore', invalid='ignore'):
        coeff = p.D_p * s['speed'] / s['p_d']
    for a, b in s['windows']:
        ax[2].plot(s['t'][a:b], coeff[a:b] * 1e12, 'C0', lw=0.5)
        ax[1].axvspan(s['t'][a], s['t'][b - 1], color='C2', alpha=0.15)
    ax[2].axhline((p.C_p + p.C_c + p.C_r) * 1e12, color='C1', ls='--',
                  label='nominal C_p + C_c + C_r')
    if k['fit'] is not None:
        ax[2].axhline(k['scale'] * (p.C_p + p.C_c + p.C_r) * 1e12, color='C0', ls='-',
                      label='identified C_p + C_c + C_r')
    ax[2].set_ylabel('D_p omega / (p_A - p_B)\n[1e-12 m^3/(s Pa)]')
    ax[2].set_xlabel('time [s]')
    ax[2].legend(fontsize=8)
    ax[0].set_title('Leakage test (thesis Fig. 3.44): held loads (steady windows shaded)')
    save_png(fig, path)


def validation_png(path: str, v: dict) -> None:
    """Fig. 3.45: the validation run against the nominal and the identified model."""
    from ..io.report import save_png
    s = v['signals']
    fig, ax = _figure(2)
    ax = ax[:, 0]
    ax[0].plot(s['t'], s['reference'] * 1e3, 'k:', lw=0.8, label='reference')
    ax[0].plot(s['t'], s['position'] * 1e3, 'k', lw=0.6, label='measured')
    for m, style in (('nominal', 'C1'), ('identified', 'C0')):
        ax[0].plot(s['t'], s[f'{m}_position'] * 1e3, style, lw=0.8,
                   label=f'{m} (median RMSE {v["position_rmse_m"][m] * 1e6:.0f} um)')
        ax[1].plot(s['t'], s[f'{m}_speed'] * RPM, style, lw=0.6,
                   label=f'{m} (median RMSE {v["motor_speed_rmse_rad_s"][m] * RPM:.0f} rpm)')
    ax[1].plot(s['t'], s['speed'] * RPM, 'k', lw=0.5, label='measured')
    ax[0].set_ylabel('position [mm]')
    ax[1].set_ylabel('motor speed [rpm]')
    ax[1].set_xlabel('time [s]')
    for a in ax:
        a.legend(fontsize=8, loc='upper right')
    ax[0].set_title('Validation (thesis Fig. 3.45): the stack\'s closed loop, step and sine')
    save_png(fig, path)


def write(out_dir: str, result: dict, d: dict, f: dict, k: dict, v: dict, p) -> None:
    """Figures and report.md into out_dir."""
    drive_png(os.path.join(out_dir, 'drive_sweep.png'), d)
    if f['data'] is not None:
        friction_png(os.path.join(out_dir, 'friction.png'), f, p)
    leakage_png(os.path.join(out_dir, 'leakage.png'), k, p)
    validation_png(os.path.join(out_dir, 'validation.png'), v)
    sweep = result['drive_sweep']
    val = result['validation']
    lines = ['# System identification (thesis sec. 3.6)', '',
             'Grey box: the parameters of the plant model plant_sim runs, fitted to the '
             'recordings below; 95 % intervals; "identified" when the interval\'s half-width is '
             f'at most {result["criteria"]["identified_max_relative_half_width"] * 100:.0f} % '
             'of the value and no correlation with another fitted parameter reaches '
             f'{result["criteria"]["identified_max_correlation"]}. Method: '
             'docs/identification.md.', '', '## Recordings', '']
    for exp, r in result['recordings'].items():
        lines.append(f'- {exp}: `{r["path"]}` ({r["duration_s"]:.1f} s, {r["plant_side"]})')
    lines += ['', '## Parameters', '',
              '| parameter | value | 95 % interval | nominal | unit | identified | note |',
              '|---|---|---|---|---|---|---|']
    for name, e in result['parameters'].items():
        unit, scale = UNITS.get(name, ('', 1.0))
        lines.append(f'| {name} | {_num(e["value"], scale)} | {_num(e["ci_low"], scale)} .. '
                     f'{_num(e["ci_high"], scale)} | {_num(e["nominal"], scale)} | {unit} | '
                     f'{"yes" if e["identified"] else "no"} | {e["note"]} |')
    lines += ['', 'identified.yaml holds: ' + (', '.join(f'`{key}`' for key in
                                                          result['identified_yaml']) or 'nothing'),
              '', '## Drive sweep (Fig. 3.36)', '', '![drive sweep](drive_sweep.png)', '',
              'Motor speed, measured against the plant\'s drive replayed with the recorded speed '
              'references and the measured load pressure: RMSE '
              f'{sweep["motor_speed_rmse_rad_s"]["nominal"] * RPM:.1f} rpm nominal, '
              f'{sweep["motor_speed_rmse_rad_s"]["identified"] * RPM:.1f} rpm identified (max '
              f'{sweep["motor_speed_max_error_rad_s"]["identified"] * RPM:.1f} rpm; the thesis: '
              '27 rpm, max 117 rpm).', '', '## Friction (Fig. 3.42)', '']
    if f['data'] is not None:
        lines += ['![friction](friction.png)', '',
                  'Force from the chamber pressures less the piston\'s inertia against the '
                  'piston velocity, with eq. 3.33 fitted: RMSE '
                  f'{f["force_rmse_n"]["nominal"]:.0f} N nominal, '
                  f'{f["force_rmse_n"]["identified"]:.0f} N identified.', '']
    else:
        lines += [result['parameters']['friction.F_c']['note'], '']
    lines += ['## Leakage (Fig. 3.44)', '', '![leakage](leakage.png)', '',
              '| load [kN] | p_A - p_B [bar] | motor speed [rpm] | D_p omega / dp [m^3/(s Pa)] |',
              '|---|---|---|---|']
    for lv in result['leakage']['levels']:
        lines.append(f'| {lv["load_n"] * 1e-3:.1f} | {lv["p_d_pa"] * 1e-5:.1f} | '
                     f'{lv["motor_speed_rad_s"] * RPM:.0f} | {lv["leakage_m3_s_pa"]:.3g} |')
    lines += ['', '## Validation (Fig. 3.45)', '', '![validation](validation.png)', '',
              f'RMSE against the recording, the median over {len(val["seeds"])} sensor-noise '
              'draws (the figure shows the first). The floor is what the identified model '
              'scores against a simulated recording of itself with other noise: what an exact '
              'model would get. Excess: (identified - floor) / (nominal - floor), where the '
              'nominal error is well above the floor.', '',
              '| model | position RMSE [um] | motor speed RMSE [rpm] |', '|---|---|---|']
    pos, spd = val['position_rmse_m'], val['motor_speed_rmse_rad_s']
    for m in ('nominal', 'identified', 'floor'):
        lines.append(f'| {m} | {pos[m] * 1e6:.1f} | {spd[m] * RPM:.1f} |')
    lines.append('| excess | ' + ' | '.join(
        f'{q["excess"]:.2f}' if q['judged'] else 'not judged (nominal within 2x the floor)'
        for q in (pos, spd)) + ' |')
    shaky = sorted({m for q in (pos, spd) for m, ok in q['repeatable'].items() if not ok})
    if shaky:
        lines += ['', f'Not repeatable under the sensor noise: the {" and the ".join(shaky)} '
                  'model (its draws\' RMSEs differ by more than 3x: a loop that sticks and '
                  'slips, or trips), so its figure and the floor say little.']
    tmp = os.path.join(out_dir, 'report.md.tmp')
    with open(tmp, 'w') as fh:
        fh.write('\n'.join(lines) + '\n')
    os.replace(tmp, os.path.join(out_dir, 'report.md'))
