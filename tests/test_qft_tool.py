"""scripts/design_qft end to end: infeasible spec, --quick run, and the shipped design."""
import os
import subprocess
import sys

import numpy as np
import pytest

from eha_ros.core.config.params import load
from eha_ros.core.plant.parameters import PLANT_SCHEMA
from eha_ros.core.qft import cost, family, report
from eha_ros.core.qft.spec import load_spec

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _run(*args, timeout=120):
    return subprocess.run([sys.executable, '-m', 'eha_ros.tools.design_qft', *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def test_infeasible_spec_one_line_exit_2(tmp_path):
    spec = tmp_path / 'bad.yaml'
    spec.write_text('design_qft:\n  ros__parameters:\n    position: {a_up: 1.0}\n')
    r = _run('--spec', str(spec), '--out', str(tmp_path / 'c.yaml'), '--report-dir',
             str(tmp_path / 'rep'), '--quick', '--no-crosscheck')
    assert r.returncode == 2
    err = [ln for ln in r.stderr.splitlines() if 'error' in ln]
    assert len(err) == 1
    assert err[0].startswith('design_qft: error: infeasible specification at ')
    assert 'tracking' in err[0] and 'rad/s' in err[0]
    assert not (tmp_path / 'c.yaml').exists()


def test_unknown_spec_key_one_line(tmp_path):
    spec = tmp_path / 'bad.yaml'
    spec.write_text('design_qft:\n  ros__parameters:\n    position: {Wss: 1.3}\n')
    r = _run('--spec', str(spec), '--out', str(tmp_path / 'c.yaml'))
    assert r.returncode == 2 and r.stderr.strip().count('\n') == 0
    assert "position.Wss" in r.stderr


def test_zp_box_beyond_nyquist_refused_one_line(tmp_path):
    spec = tmp_path / 'bad.yaml'
    spec.write_text('design_qft:\n  ros__parameters:\n    position: {zp_max: 20000.0}\n')
    r = _run('--spec', str(spec), '--out', str(tmp_path / 'c.yaml'))
    assert r.returncode == 2 and r.stderr.strip().count('\n') == 0
    assert 'position.zp_max' in r.stderr and 'pi/(2 digital.Ts)' in r.stderr


def _drive_gains(plant_path):
    p = load(PLANT_SCHEMA, [plant_path])
    return p['plant.motor.k_T'], [p['plant.drive.Kp_w'], p['plant.drive.Ki_w'], p['plant.drive.lowpass_w']]


def test_quick_design_end_to_end(tmp_path):
    out = tmp_path / 'controller.yaml'
    plant = tmp_path / 'plant.yaml'
    orig = open(os.path.join(ROOT, 'config/plant.yaml'), encoding='utf-8').read()
    plant.write_text(orig)
    # a hang guard, not a speed test: the quick design takes 85-95 s alone on this 2-core machine
    r = _run('--quick', '--out', str(out), '--report-dir', str(tmp_path / 'rep'), '--seed', '3',
             '--plant', str(plant), '--update-plant-yaml', timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert 'iteration' in r.stderr                       # progress shown
    assert 'T_d = 2.5 ms' in r.stderr and 'plant.drive.Kp_w = ' in r.stdout
    Gv, G, F = report.read_controller_yaml(str(out))
    # eq. 4.74 with 3 pairs plus one second-order section (config/qft_spec.yaml)
    assert len(G.poles) == 6 and 0.0 in G.poles and len(G.zeros) == 5 and len(Gv.poles) == 2
    # realisable at Ts: every zero/pole of G inside the box [0.5, 1500] rad/s (|.| for pairs)
    assert all(0.5 * (1 - 1e-9) <= abs(v) <= 1500 * (1 + 1e-9) for v in G.zeros + G.poles if v != 0)
    assert all(np.real(v) < 0 for v in G.zeros + G.poles if v != 0)
    assert 'G minimax' in r.stderr                      # refinement progress shown
    # --update-plant-yaml: only the three drive lines change, comments/layout kept
    new = plant.read_text()
    diff = [(a, b) for a, b in zip(orig.split('\n'), new.split('\n')) if a != b]
    assert len(orig.split('\n')) == len(new.split('\n')) and len(diff) == 3
    assert [d[1].split(':')[0].strip() for d in diff] == ['Kp_w', 'Ki_w', 'lowpass_w']
    assert all('design_qft' in d[1] and 'eq. 4.71' in d[1] for d in diff)
    k_T, K = _drive_gains(str(plant))
    assert np.allclose(cost.x_of_velocity(Gv, k_T), np.log10(K), rtol=0, atol=1e-9)
    assert (tmp_path / 'controller_thesis.yaml').exists()
    for name in ('report.md', 'report.json', 'nichols_position.png', 'nichols_velocity.png',
                 'bode_closed_loop_designed.png', 'pso_convergence.png'):
        assert (tmp_path / 'rep' / name).stat().st_size > 0


def _analyse(path):
    spec = load_spec(os.path.join(ROOT, 'config/qft_spec.yaml'))
    plant = load(PLANT_SCHEMA, [os.path.join(ROOT, 'config/plant.yaml')])
    fam = family.build_family(plant, spec)
    Gv, G, F = report.read_controller_yaml(os.path.join(ROOT, path))
    from eha_ros.tools.design_qft import analyse_set
    poles = report.read_antiwindup_poles(os.path.join(ROOT, path))
    return analyse_set(fam, spec, Gv, G, F, aw_poles=poles)[0], G


def test_shipped_design_meets_every_check():
    """config/controller.yaml, the stack's controller (scripts/design_qft --seed 3 with the
    shipped spec) on every plant: eigenvalues, dense-grid specs, design-frequency bounds, nominal
    bandwidth >= 9 Hz, loop delay and the digital loop: every check, including the dynamic
    stiffness of eq. 4.60 up to 7 Hz and the circle criterion of its anti-windup
    (Re H >= 0 on every plant). No PSO rerun."""
    r, G = _analyse('config/controller.yaml')
    assert 'aw_circle' in r['pass']
    failed = [k for k, v in r['pass'].items() if not v]
    assert not failed, (failed, {k: v for k, v in r.items() if not k.startswith('step_nominal_')})
    assert r['all_pass'] and r['pos_stiff_worst_db'] <= 0.0 and r['pos_stiffness_min_N_per_mm'] >= 49e3
    assert r['bw_nominal_hz'] >= 9.0
    # the loop delay and the digital checks are part of the verdict
    assert r['loop_delay_ms'] == pytest.approx(2.5) and r['dig_delay_samples'] == 2
    for key in ('dig_stable', 'dig_agree', 'step_nominal', 'step_family'):
        assert r['pass'][key]
    assert r['step_overshoot_pct'] <= 5.0 and r['step_settling_s'] <= 0.3
    # realisable at Ts = 1 ms: all controller corners below pi/(2 Ts)
    assert max(abs(v) for v in G.poles + G.zeros) <= 1500.0 * (1 + 1e-9) < np.pi / (2 * 1e-3)


# The earlier design (config/controller_eq474.yaml, eq. 4.74 only, corners <= 1000 rad/s,
# K = 660800), kept as an alternative, misses the stiffness of eq. 4.60 at 10-50 rad/s on the
# leakiest plants (3.3 dB on the dense grid, 3.8 dB at 50 rad/s); every other check passes.
# Upper limits on the miss (dB) so that a regression still fails:
STIFFNESS_GAP_DB = {'pos_stiffness': ('pos_stiff_worst_db', 3.6),
                    'pos_bounds': ('pos_bound_violation_db', 4.0)}


def test_eq474_alternative_checks_and_its_stiffness_gap():
    r, G = _analyse('config/controller_eq474.yaml')
    failed = [k for k, v in r['pass'].items() if not v and k not in STIFFNESS_GAP_DB]
    assert not failed, (failed, {k: v for k, v in r.items() if not k.startswith('step_nominal_')})
    for key, (fig, limit) in STIFFNESS_GAP_DB.items():
        assert 0.0 < r[fig] <= limit, (key, r[fig])
    assert r['bw_nominal_hz'] >= 9.0 and max(abs(v) for v in G.poles + G.zeros) <= 1000.0 * (1 + 1e-9)


def test_stiff_design_keeps_steady_accuracy_with_the_friction_lowpass(tmp_path):
    """Batch stack (nonlinear plant, sensor noise, chamber Kalman filter), 5 mm step, seeds 1-3,
    the stiff design (config/controller.yaml) against the eq. 4.74 alternative. Its gain above
    1000 rad/s makes the speed command chatter, and eq. 4.36 takes the friction's sign from the pump speed: without the
    estimator's friction low-pass (estimator.model.friction_lowpass: 0) the modelled +-800 N
    flips with the chatter, the filter drifts from the truth and the piston ends tens of um off
    target (and the command gets noisier still). With the 50 Hz default it ends within 20 um,
    like the eq. 4.74 design."""
    import shutil
    from eha_ros.core.sim.batch import BatchStack
    eq474 = tmp_path / 'config'
    shutil.copytree(os.path.join(ROOT, 'config'), eq474)
    shutil.copy(eq474 / 'controller_eq474.yaml', eq474 / 'controller.yaml')
    stiff = os.path.join(ROOT, 'config')
    res = {}
    for name, d, lp in (('eq474', str(eq474), None),
                        ('stiff', stiff, None), ('stiff, no low-pass', stiff, 0.0)):
        ov = {} if lp is None else \
            {'estimator': {'estimator:estimator.model.friction_lowpass': lp}}
        err, noise = [], []
        for seed in (1, 2, 3):
            out = BatchStack(config_dir=d, seed=seed, overrides=ov).run(np.r_[np.zeros(1000), np.full(1500, 0.005)])
            x, u = out['truth'][1000:], out['command'][1000:]
            err.append(abs(np.mean(x[1000:1400]) - 0.005))
            noise.append(np.std(u[1000:1400]))
        res[name] = (max(err), float(np.mean(noise)))
    print('5 mm step, worst steady error [m] and command noise [rad/s]:', res)
    assert res['eq474'][0] <= 20e-6 and res['stiff'][0] <= 20e-6
    # with the adaptive states of issue 15 the filter no longer drifts without the low-pass
    # either (5.6 um; was 65 um): printed, not asserted
    print(res)   # no-low-pass command noise: measured, not asserted since issue 15


def test_drive_gains_equal_designed_velocity_controller():
    """The simulated drive (config/plant.yaml) runs the designed G_v of config/controller.yaml."""
    k_T, K = _drive_gains(os.path.join(ROOT, 'config/plant.yaml'))
    Gv = report.read_controller_yaml(os.path.join(ROOT, 'config/controller.yaml'))[0]
    K_ctrl = 10 ** cost.x_of_velocity(Gv, k_T)
    assert np.allclose(K_ctrl, K, rtol=1e-6, atol=0), (K_ctrl, K)
