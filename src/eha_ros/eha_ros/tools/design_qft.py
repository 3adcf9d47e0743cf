"""design_qft: QFT + PSO design of the EHA cascade controllers (thesis section 4.3).

Velocity loop G_v (eq. 4.65) by PSO on the speed plant omega/i_ref of eq. 3.35, then position
controller G (eq. 4.74) by PSO on the family of closed velocity loops, then prefilter F (4.77),
then the anti-windup poles of G (qft.antiwindup: circle criterion on the family, saturating
runs on the nonlinear plant). Writes the controller YAML, the thesis' own controllers, and a
report (markdown, JSON, PNGs) comparing both on every plant of the family. With --antiwindup
FILE only the anti-windup poles of an existing controller YAML are designed and written."""
from __future__ import annotations

import argparse
import datetime as dt
import os
import sys
import time

import numpy as np

from ..core.config.cli import UsageError, guarded
from ..core.config.params import load
from ..core.plant.parameters import PLANT_SCHEMA
from ..core.qft import bounds as qb
from ..core.qft import antiwindup as aw
from ..core.controller import lti
from ..core.qft import minimax, cost, family, plots, prefilter, pso, report, verify
from ..core.qft.spec import load_spec

PROG = 'design_qft'


def parse(argv):
    ap = argparse.ArgumentParser(prog=PROG, description=__doc__.splitlines()[0] + ' Writes '
                                 'the controller YAML loaded by the controller node.')
    ap.add_argument('--spec', default='config/qft_spec.yaml', help='QFT specification (ROS params file, node design_qft)')
    ap.add_argument('--plant', default='config/plant.yaml', help='nominal plant parameters')
    ap.add_argument('--plant-params', default=None, metavar='FILE',
                    help='plant.* keys of FILE over --plant: an identified plant '
                         '(scripts/identify\'s identified.yaml) as the family\'s nominal plant')
    ap.add_argument('--out', default='config/controller.yaml',
                    help='designed controller YAML (default: the one the stack runs)')
    ap.add_argument('--antiwindup', metavar='FILE', default=None,
                    help='only design the anti-windup poles of the controller in FILE and write '
                         'them into it (1-3 min)')
    ap.add_argument('--thesis-out', default=None,
                    help='thesis controllers (eqs. 4.71, 4.76, 4.77) YAML; default: '
                         'controller_thesis.yaml next to --out')
    ap.add_argument('--report-dir', default=None, help='report folder (default out/qft/<timestamp>)')
    ap.add_argument('--seed', type=int, default=1, help='PSO/DE/prefilter random seed')
    ap.add_argument('--quick', action='store_true',
                    help='few PSO iterations and a short cross-check (tests); result may not meet the specs')
    ap.add_argument('--no-crosscheck', action='store_true', help='skip the differential_evolution cross-check')
    ap.add_argument('--strict', action='store_true', help='exit 1 if the design fails any check')
    ap.add_argument('--update-plant-yaml', action='store_true',
                    help='write the designed velocity controller into the simulated drive: '
                         'plant.drive.Kp_w, Ki_w, lowpass_w of --plant (text substitution)')
    return ap.parse_args(argv)


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def progress(name, total):
    t0 = time.time()

    def cb(k, best):
        log(f'[{name}] iteration {k:3d}/{total}  best cost {best:.5g}  ({time.time() - t0:.1f} s)')
    return cb


DRIVE_KEYS = (('Kp_w', '[Nm/(rad/s)] velocity loop P gain K_1 (times 1/k_T)', '0.45'),
              ('Ki_w', '[Nm/rad] velocity loop I gain K_2 (times 1/k_T)', '56'),
              ('lowpass_w', '[rad/s] velocity loop low-pass K_3', '2555'))


def g_text(K, z, p, bq):
    """One-line G(s) of eq. 4.74 (plus second-order sections) for logs and the YAML header."""
    txt = (f'{K:g}/s prod (1 + s/z_i)/(1 + s/p_i), z = {[float(f"{v:.6g}") for v in z]}, '
           f'p = {[float(f"{v:.6g}") for v in p]}')
    for b in bq:
        txt += (f' x (s^2/{b["wz"]:.6g}^2 + 2 {b["zeta_z"]:.4g} s/{b["wz"]:.6g} + 1)'
                f'/(s^2/{b["wp"]:.6g}^2 + 2 {b["zeta_p"]:.4g} s/{b["wp"]:.6g} + 1)')
    return txt


def update_plant_yaml(path, K, when=''):
    """Rewrite exactly plant.drive.Kp_w, Ki_w, lowpass_w (= K1, K2, K3 of eq. 4.65) in a plant
    YAML, keeping every other line, comment and the indentation."""
    import re
    try:
        with open(path, encoding='utf-8') as fh:
            lines = fh.read().split('\n')
    except OSError as err:
        raise UsageError(f'cannot read {path}: {err}') from None
    # the drive: block (its indentation) and its direct children
    start = [i for i, ln in enumerate(lines) if re.match(r'^\s*drive:\s*(#.*)?$', ln)]
    if len(start) != 1:
        raise UsageError(f'{path}: expected exactly one "drive:" block, found {len(start)}')
    ind0 = len(lines[start[0]]) - len(lines[start[0]].lstrip())
    end = start[0] + 1
    while end < len(lines) and (not lines[end].strip() or lines[end].lstrip().startswith('#') or
                                len(lines[end]) - len(lines[end].lstrip()) > ind0):
        end += 1
    for (key, what, thesis), val in zip(DRIVE_KEYS, K):
        hits = [i for i in range(start[0] + 1, end)
                if re.match(rf'^\s*{key}:\s*[^\s#]+', lines[i])]
        if len(hits) != 1:
            raise UsageError(f'{path}: expected one plant.drive.{key} line, found {len(hits)}')
        i = hits[0]
        ind = lines[i][:len(lines[i]) - len(lines[i].lstrip())]
        lines[i] = (f'{ind}{key}: {float(val)!r}  # {what}; G_v of eq. 4.65 from scripts/design_qft'
                    f'{" " + when if when else ""}; thesis eq. 4.71: {thesis}')
    with open(path, 'w', encoding='utf-8') as fh:
        fh.write('\n'.join(lines))


def analyse_set(fam, spec, Gv, G, F, aw_poles=None):
    bv = qb.velocity_bounds(spec, lambda w: family.torque_responses(fam, w)[0])
    casc = family.velocity_loop_plants(fam, Gv, spec.loop_delay(fam.drive_delay))
    bp = qb.position_bounds(spec, casc.P_omega, casc.P_d)
    return verify.analyse(fam, spec, Gv, G, F, bv, bp, aw_poles), bv, bp, casc


def design_antiwindup(G, F, casc, spec, fam, plant, seed, quick, start=None):
    """Anti-windup poles of G and their figures (qft.antiwindup.design), logged."""
    log(f'{PROG}: anti-windup poles of G (circle criterion on {fam.n} plants, saturating runs on '
        f'the nonlinear plant) ...')
    t0 = time.time()
    poles, figs = aw.design(G, F.num_den(), verify.digital_loop(casc, spec, fam),
                            verify.dense_grid(spec), plant, seed=seed, maxiter=2 if quick else 15,
                            maxfev=20 if quick else 150, start=start)
    log(f'{PROG}: anti-windup poles {np.round(poles, 2).tolist()} rad/s ({time.time() - t0:.0f} s): '
        f'min Re H {figs["aw_circle_min_re"]:.3g}; 40 mm step overshoot '
        f'{figs["step_40mm_overshoot_pct"]:.2f} %, held 1 s then released '
        f'{figs["held_release_overshoot_pct"]:.2f} %, 2 mm jump {figs["jump_2mm_overshoot_pct"]:.2f} %')
    return poles, figs


def antiwindup_only(a, spec, plant):
    """--antiwindup FILE: design the poles for the controller in FILE, rewrite FILE with them."""
    Gv, G, F = report.read_controller_yaml(a.antiwindup)
    with open(a.antiwindup, encoding='utf-8') as fh:
        head = []
        for ln in fh:
            if not ln.startswith('#') or ln.startswith('# units:'):
                break
            head.append(ln[2:].rstrip('\n'))
    fam = family.build_family(plant, spec)
    casc = family.velocity_loop_plants(fam, Gv, spec.loop_delay(fam.drive_delay))
    poles, figs = design_antiwindup(G, F, casc, spec, fam, plant, a.seed, a.quick,
                                    start=report.read_antiwindup_poles(a.antiwindup))
    head = [h for h in head if not h.startswith('anti-windup:')]
    head.append(f'anti-windup: poles by scripts/design_qft --antiwindup (seed {a.seed}, '
                f'{dt.datetime.now().isoformat(timespec="seconds")}): min Re H '
                f'{figs["aw_circle_min_re"]:.3g} on the family; nonlinear nominal plant: 40 mm step '
                f'{figs["step_40mm_overshoot_pct"]:.2f} %, held 1 s then released '
                f'{figs["held_release_overshoot_pct"]:.2f} %')
    report.write_controller_yaml(a.antiwindup, Gv, G, F, '\n'.join(head), aw_poles=poles)
    log(f'{PROG}: wrote the anti-windup poles into {a.antiwindup}')
    return 0


def load_plant(a) -> dict:
    """The design's nominal plant: --plant, with the plant.* keys of --plant-params over it
    (core.hardware.sim_params.plant_file: one line for a bad file)."""
    if not a.plant_params:
        return load(PLANT_SCHEMA, [a.plant])
    if a.update_plant_yaml:
        raise UsageError('--update-plant-yaml writes the designed drive into --plant; with '
                         '--plant-params the drive is the identified one: give one of them')
    from ..core.hardware.sim_params import plant_file
    return load(PLANT_SCHEMA, [a.plant], plant_file(a.plant_params))


def main(argv=None):
    a = parse(sys.argv[1:] if argv is None else argv)
    spec = load_spec(a.spec)
    plant = load_plant(a)
    if a.antiwindup:
        return antiwindup_only(a, spec, plant)
    stamp = dt.datetime.now().strftime('%Y%m%d-%H%M%S')
    rdir = a.report_dir or os.path.join('out', 'qft', stamp)
    try:
        os.makedirs(rdir, exist_ok=True)
        os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    except OSError as err:
        raise UsageError(f'cannot create output folder: {err}') from None
    t_start = time.time()
    fam = family.build_family(plant, spec)
    log(f'{PROG}: family of {fam.n} plants, velocity design frequencies {[float(v) for v in spec.velocity_freqs]} rad/s')
    pp = dict(particles=spec['pso.particles'], W=spec['pso.W'], C1=spec['pso.C1'],
              C2=spec['pso.C2'], v_max_frac=spec['pso.v_max_frac'], seed=a.seed)
    it_v = 4 if a.quick else spec['velocity.iterations']
    it_p = 4 if a.quick else spec['position.iterations']
    if a.quick:
        pp['particles'] = min(pp['particles'], 12)
    summary = {'spec': a.spec, 'plant': a.plant, 'plant_params': a.plant_params, 'seed': a.seed,
               'quick': a.quick}

    # velocity loop
    bv = qb.velocity_bounds(spec, lambda w: family.torque_responses(fam, w)[0])
    qb.check_feasible(bv, spec, 'velocity')
    vc = cost.VelocityCost(fam, spec, bv)
    lo_v, hi_v = np.log10(spec['velocity.K_min']), np.log10(spec['velocity.K_max'])
    rv = pso.pso(vc, lo_v, hi_v, iterations=it_v, progress=progress('G_v PSO', it_v), **pp)
    Gv = cost.velocity_ctrl(rv.x, fam.k_T_nominal)
    K1, K2, K3 = (10 ** rv.x).tolist()
    summary['velocity'] = {'K1': K1, 'K2': K2, 'K3': K3, 'pso_cost': rv.cost}
    log(f'{PROG}: G_v = (1/k_T)({K1:.4g} + {K2:.4g}/s)/(s/{K3:.4g} + 1), cost {rv.cost:.4g}')
    drive_msg = (f'drive settings (config/plant.yaml, the drive applies 1/k_T): plant.drive.Kp_w = '
                 f'{K1!r} (K1), plant.drive.Ki_w = {K2!r} (K2), plant.drive.lowpass_w = {K3!r} (K3)')
    log(f'{PROG}: {drive_msg}')
    T_d = spec.loop_delay(fam.drive_delay)
    summary['loop_delay_s'] = T_d
    summary['Ts'] = spec['digital.Ts']
    log(f'{PROG}: position-loop delay T_d = {1e3 * T_d:.4g} ms '
        f'({"spec digital.delay" if spec["digital.delay"] >= 0 else "1.5 Ts + plant.drive.delay"}), '
        f'Ts = {spec["digital.Ts"]:g} s')

    # position loop on the family of closed velocity loops
    casc = family.velocity_loop_plants(fam, Gv, T_d)
    bp = qb.position_bounds(spec, casc.P_omega, casc.P_d)
    qb.check_feasible(bp, spec, 'position')
    pc = cost.PositionCost(casc, spec, bp)
    lo_p, hi_p = cost.position_box(spec)
    npair, nbq = spec['position.pairs'], spec['position.biquads']
    # stage 1: the thesis' PSO over the z_i, p_i of eq. 4.74 (Table 4.8)
    lo_1, hi_1 = lo_p[:2 * npair], hi_p[:2 * npair]
    rp = pso.pso(pc, lo_1, hi_1, iterations=it_p, progress=progress('G PSO', it_p), **pp)
    dx = minimax.DenseExcess(casc, spec, bp)

    def ctrl(x):
        return cost.position_ctrl(x, spec['position.K'], npair)

    # stage 2: minimax on the dense grid, from the PSO best with each second-order section
    # added as an identity (w_z = w_p, zeta_z = zeta_p) at a few start frequencies
    e_pso = float(dx(ctrl(rp.x)).max())
    starts = [rp.x]
    if nbq:
        starts = [np.clip(np.r_[rp.x, np.log10([v for k in range(nbq) for v in
                                                (w0 * 1.5 ** k, 0.5, w0 * 1.5 ** k, 0.5)])],
                          lo_p, hi_p) for w0 in (300.0, 600.0, 1000.0)]
    log(f'{PROG}: minimax refinement of the PSO best on the {len(dx.w)}-point grid (SLSQP, '
        f'{len(starts)} start(s){", second-order sections start as identities" if nbq else ""}) ...')
    it_r = 10 if a.quick else 200
    best = None
    for x0 in starts:
        xr, e_r = minimax.refine(ctrl, x0, lo_p, hi_p, dx, -0.5 * spec['position.zp_min'],
                                 maxiter=it_r, progress=progress('G minimax', it_r))
        if best is None or e_r < best[1]:
            best = (xr, e_r)
    xr, e_ref = best
    log(f'{PROG}: worst spec excess on the family, dense grid: PSO best {e_pso:+.3f} dB -> '
        f'refined {e_ref:+.3f} dB (<= 0 meets every spec)')
    summary['position_refine'] = {'pso_cost': rp.cost, 'pso_worst_excess_db': e_pso,
                                  'refined_worst_excess_db': e_ref,
                                  'refined_cost': float(pc(xr[None])[0])}
    rp.x = xr
    G = ctrl(rp.x)
    zp = (10 ** rp.x).tolist()
    bq = [dict(zip(('wz', 'zeta_z', 'wp', 'zeta_p'), zp[2 * npair + 4 * k: 2 * npair + 4 * k + 4]))
          for k in range(nbq)]
    summary['position'] = {'K': spec['position.K'], 'z': zp[:npair], 'p': zp[npair:2 * npair],
                           'biquads': bq, 'pso_cost': rp.cost}
    g_txt = g_text(spec['position.K'], zp[:npair], zp[npair:2 * npair], bq)
    log(f'{PROG}: G = {g_txt}')

    if not a.no_crosscheck:
        log(f'{PROG}: cross-check with scipy differential_evolution (same costs)')
        mi = 3 if a.quick else 25
        xv, fv, nv = pso.de_crosscheck(vc, lo_v, hi_v, seed=a.seed, maxiter=mi, popsize=8)
        xp, fp, npv = pso.de_crosscheck(pc, lo_1, hi_1, seed=a.seed, maxiter=mi, popsize=8)
        summary['crosscheck'] = {'velocity': {'pso_cost': rv.cost, 'de_cost': fv, 'de_nfev': nv,
                                              'de_x': (10 ** xv).tolist()},
                                 'position': {'pso_cost': rp.cost, 'de_cost': fp, 'de_nfev': npv,
                                              'de_x': (10 ** xp).tolist()}}
        log(f'{PROG}: DE best cost velocity {fv:.4g} (PSO {rv.cost:.4g}), position {fp:.4g} (PSO {rp.cost:.4g})')

    # prefilter
    wt = prefilter.band_grid(spec, 200)
    Lt = casc.P_omega(wt) * G.freq(wt)[None]
    wf = np.logspace(-1, 4, 1500)
    Lf = casc.P_omega(wf)[-1] * G.freq(wf)
    yT = verify.digital_loop(casc, spec, fam).steps(G, spec['digital.horizon'])
    F, finfo = prefilter.design_prefilter(spec, Lt / (1 + Lt), Lf / (1 + Lf), wf, seed=a.seed,
                                          maxiter=10 if a.quick else 60, y_T=yT)
    summary['prefilter'] = finfo
    log(f'{PROG}: F corners a, b, c = {[round(v, 3) for v in finfo["corners"]]} rad/s, '
        f'tracking margin {finfo["margin_db"]:.3g} dB, nominal bandwidth {finfo["bandwidth_nominal_hz"]:.3g} Hz, '
        f'digital step worst overshoot {finfo["step_overshoot_worst_pct"]:.3g} %, '
        f'settling {finfo["step_settling_worst_s"]:.3g} s')

    # anti-windup of both controller sets
    aw_d, awf_d = design_antiwindup(G, F, casc, spec, fam, plant, a.seed, a.quick)
    Gv_t = lti.thesis_velocity(fam.k_T_nominal)
    casc_t = family.velocity_loop_plants(fam, Gv_t, T_d)
    aw_t, awf_t = design_antiwindup(lti.thesis_position(), lti.thesis_prefilter(), casc_t, spec,
                                    fam, plant, a.seed, a.quick)
    summary['antiwindup'] = {'designed': {'poles_real': aw_d.real.tolist(),
                                          'poles_imag': aw_d.imag.tolist(), **awf_d},
                             'thesis': {'poles_real': aw_t.real.tolist(),
                                        'poles_imag': aw_t.imag.tolist(), **awf_t}}

    # analysis of both controller sets
    res_d = verify.analyse(fam, spec, Gv, G, F, bv, bp, aw_poles=aw_d)
    res_t, bv_t, bp_t, casc_t = analyse_set(fam, spec, Gv_t, lti.thesis_position(),
                                            lti.thesis_prefilter(), aw_poles=aw_t)
    summary['phase_grid_step_deg'] = spec['bounds.phase_step_deg']
    summary['phase_resolution_db'] = {
        'velocity': dict(zip([f'{w:g}' for w in bv.w], qb.phase_resolution_db(bv.merged).tolist())),
        'position': dict(zip([f'{w:g}' for w in bp.w], qb.phase_resolution_db(bp.merged).tolist()))}
    summary['designed'] = res_d
    summary['thesis'] = res_t
    summary['elapsed_s'] = time.time() - t_start

    # files
    header = (f'QFT design by scripts/design_qft: spec {a.spec}, plant {a.plant}'
              f'{" + " + a.plant_params if a.plant_params else ""}, seed {a.seed}'
              f'{", QUICK (not a full design)" if a.quick else ""}, {dt.datetime.now().isoformat(timespec="seconds")}\n'
              f'G_v = (1/k_T)({K1:.6g} + {K2:.6g}/s)/(s/{K3:.6g} + 1), k_T = {fam.k_T_nominal}\n'
              f'G = {g_txt}\n'
              f'F corners (a, b, c) = {[float(f"{v:.6g}") for v in finfo["corners"]]} rad/s\n'
              f'position-loop delay T_d = {1e3 * T_d:.4g} ms (1.5 Ts + plant.drive.delay), Ts = {spec["digital.Ts"]:g} s, '
              f'digital check: ZOH plant, {spec.delay_samples(fam.drive_delay)} delay samples, Tustin G and F\n'
              f'drive gains (plant.drive.Kp_w, Ki_w, lowpass_w) = ({K1:.6g}, {K2:.6g}, {K3:.6g})\n'
              f'all checks on the {fam.n}-plant family: {"PASS" if res_d["all_pass"] else "FAIL"} (report {rdir})\n'
              f'anti-windup: min Re H {awf_d["aw_circle_min_re"]:.3g} on the family; nonlinear nominal plant: '
              f'40 mm step {awf_d["step_40mm_overshoot_pct"]:.2f} %, held 1 s then released '
              f'{awf_d["held_release_overshoot_pct"]:.2f} %')
    report.write_controller_yaml(a.out, Gv, G, F, header, aw_poles=aw_d)
    if a.update_plant_yaml:
        update_plant_yaml(a.plant, (K1, K2, K3), f'(seed {a.seed}, report {rdir})')
        log(f'{PROG}: updated plant.drive.Kp_w, Ki_w, lowpass_w in {a.plant}')
    tout = a.thesis_out or os.path.join(os.path.dirname(os.path.abspath(a.out)), 'controller_thesis.yaml')
    report.write_controller_yaml(tout, Gv_t, lti.thesis_position(), lti.thesis_prefilter(),
                                 'Thesis controllers: G_v eq. 4.71, G eq. 4.76, F eq. 4.77 '
                                 f'(written by scripts/design_qft, k_T = {fam.k_T_nominal}); '
                                 'anti-windup poles designed for them', aw_poles=aw_t)
    plots.nichols(os.path.join(rdir, 'nichols_velocity.png'), bv,
                  lambda w: family.torque_responses(fam, w)[0][-1] * Gv.freq(w),
                  'velocity loop: merged bounds and designed L_v0')
    plots.nichols(os.path.join(rdir, 'nichols_position.png'), bp,
                  lambda w: casc.P_omega(w)[-1] * G.freq(w), 'position loop: merged bounds and designed L0')
    plots.nichols(os.path.join(rdir, 'nichols_position_thesis.png'), bp_t,
                  lambda w: casc_t.P_omega(w)[-1] * lti.thesis_position().freq(w),
                  'position loop: bounds (thesis G_v) and thesis L0 (eq. 4.76)')
    wb = np.logspace(-1, np.log10(2000), 600)
    for name, (cs, Gx, Fx) in {'designed': (casc, G, F),
                               'thesis': (casc_t, lti.thesis_position(), lti.thesis_prefilter())}.items():
        Lb = cs.P_omega(wb) * Gx.freq(wb)[None]
        plots.closed_loop_bode(os.path.join(rdir, f'bode_closed_loop_{name}.png'), wb,
                               Fx.freq(wb)[None] * Lb / (1 + Lb), spec,
                               f'closed-loop family F T ({name})')
    plots.steps(os.path.join(rdir, 'step_digital.png'), {'designed': res_d, 'thesis': res_t}, spec)
    plots.convergence(os.path.join(rdir, 'pso_convergence.png'),
                      {'G_v (velocity)': rv.history, 'G (position)': rp.history})
    box_bq = (f'; second-order sections: w in the same box, zeta in [{spec["position.zeta_min"]:g}, '
              f'{spec["position.zeta_max"]:g}]' if spec['position.biquads'] else '')
    md = ['# QFT design report', '', '```', header, '```', '',
          f'Family: {fam.n} plants (Table 4.5 grid), nominal = plant.yaml x {spec["family.nominal_scale"]}.',
          'Velocity loop designed on omega/i_ref (speed output of eq. 3.35; the thesis writes P_i in 4.52).',
          f'Dense-grid checks: {spec["verify.n_points"]} points {spec["verify.w_min"]}..{spec["verify.w_max"]} rad/s; '
          f'sensitivity and stiffness up to {spec["verify.band_max_hz"]} Hz; tracking up to {spec["prefilter.w_max"]} rad/s '
          f'with tolerance {spec["position.track_tol_db"]} dB.',
          f'Every position-loop response (bounds, PSO costs, prefilter, dense checks) includes the loop '
          f'delay e^(-j w T_d), T_d = {1e3 * T_d:.4g} ms = 1.5 Ts + plant.drive.delay (one sample from '
          f'measurement to applied command, ZOH ~ Ts/2, drive FIFO {1e3 * fam.drive_delay:g} ms); eigenvalues use '
          f'a 4th-order Pade cascade. Digital rows: each closed velocity loop ZOH-discretised at Ts = '
          f'{spec["digital.Ts"]:g} s, {spec.delay_samples(fam.drive_delay)} shift states, G and F by Tustin '
          f'(controller/discrete.py, prewarp {spec["digital.prewarp_w"] or "none"}), step {1e3 * spec["digital.step"]:g} mm.',
          f'PSO box of z_i, p_i: [{spec["position.zp_min"]:g}, {spec["position.zp_max"]:g}] rad/s{box_bq}. '
          f'The PSO best is refined by SLSQP minimax of the worst spec excess on the dense grid '
          f'({summary["position_refine"]["pso_worst_excess_db"]:+.3f} dB -> {summary["position_refine"]["refined_worst_excess_db"]:+.3f} dB).',
          f'Simulated drive: {drive_msg}{" (written to " + a.plant + ")" if a.update_plant_yaml else ""}.', '',
          report.markdown({'designed': res_d, 'thesis (4.71/4.76/4.77)': res_t}), '',
          f'Phase grid {spec["bounds.phase_step_deg"]} deg: worst bound change between adjacent phases (dB) = '
          f'{summary["phase_resolution_db"]}', '',
          'Figures: nichols_velocity.png, nichols_position.png, nichols_position_thesis.png, '
          'bode_closed_loop_designed.png, bode_closed_loop_thesis.png, step_digital.png, pso_convergence.png']
    with open(os.path.join(rdir, 'report.md'), 'w', encoding='utf-8') as fh:
        fh.write('\n'.join(md) + '\n')
    report.write_json(os.path.join(rdir, 'report.json'), summary)
    print(report.markdown({'designed': res_d, 'thesis': res_t}))
    print(f'{PROG}: {drive_msg}')
    print(f'{PROG}: wrote {a.out}, {tout} and report {rdir} in {summary["elapsed_s"]:.1f} s; '
          f'designed controller {"meets every check" if res_d["all_pass"] else "FAILS some checks"} '
          f'on all {fam.n} plants')
    return 1 if (a.strict and not res_d['all_pass']) else 0


def run():
    sys.exit(guarded(PROG, main))


if __name__ == '__main__':
    run()
