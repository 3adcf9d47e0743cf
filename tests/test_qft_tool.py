"""scripts/design_qft end to end: infeasible spec, --quick run, and the shipped design."""
import os
import subprocess
import sys

import numpy as np
import pytest

from eha_ros.core.params import load
from eha_ros.core.plant.parameters import PLANT_SCHEMA
from eha_ros.core.qft import family, report, verify
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


def test_quick_design_end_to_end(tmp_path):
    out = tmp_path / 'controller.yaml'
    r = _run('--quick', '--out', str(out), '--report-dir', str(tmp_path / 'rep'), '--seed', '3')
    assert r.returncode == 0, r.stderr[-2000:]
    assert 'iteration' in r.stderr                       # progress shown
    Gv, G, F = report.read_controller_yaml(str(out))
    assert len(G.poles) == 4 and 0.0 in G.poles and len(Gv.poles) == 2
    assert (tmp_path / 'controller_thesis.yaml').exists()
    for name in ('report.md', 'report.json', 'nichols_position.png', 'nichols_velocity.png',
                 'bode_closed_loop_designed.png', 'pso_convergence.png'):
        assert (tmp_path / 'rep' / name).stat().st_size > 0


def test_shipped_design_meets_every_check():
    """config/controller.yaml (committed design) on every plant: eigenvalues, dense-grid specs,
    design-frequency bounds, nominal bandwidth >= 9 Hz. No PSO rerun."""
    spec = load_spec(os.path.join(ROOT, 'config/qft_spec.yaml'))
    plant = load(PLANT_SCHEMA, [os.path.join(ROOT, 'config/plant.yaml')])
    fam = family.build_family(plant, spec)
    Gv, G, F = report.read_controller_yaml(os.path.join(ROOT, 'config/controller.yaml'))
    from eha_ros.tools.design_qft import analyse_set
    r = analyse_set(fam, spec, Gv, G, F)[0]
    failed = [k for k, v in r['pass'].items() if not v]
    assert not failed, (failed, r)
    assert r['bw_nominal_hz'] >= 9.0
