"""Sweep runs: interrupted sessions keep finished points; the main job in batch; bad options."""
import json
import os
import subprocess

import numpy as np
import pytest
from scipy import signal as sps

from eha_ros.core.sweep.session import SweepSession
from eha_ros.core.sweep.signals import SteppedSine

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RUN = os.path.join(ROOT, 'scripts', 'run')


def test_interrupted_session_keeps_finished_points(tmp_path):
    plan = SteppedSine(1, 2, 9, 6, 0.1, 1e-3)
    s = SweepSession(plan, str(tmp_path), {'mode': 'stepped'}, background_writes=False)
    s.start(100)
    sys_ = sps.dlti([0.2], [1, -0.8], dt=1e-3)                 # a known first-order lag
    _, y = sps.dlsim(sys_, plan.array())
    y = y[:, 0]
    stop = plan.segments[2].stop + 40                           # in the 4th frequency
    for i in range(stop):
        s.record('reference', 100 + i, plan.array()[i])
        s.record('truth', 100 + i, y[i])
        s.progress(100 + i)
    summary = s.finish(reason='interrupted')
    on_disk = json.load(open(tmp_path / 'summary.json'))
    assert on_disk['complete'] is False and on_disk['status'] == 'interrupted'
    assert [p['freq_hz'] for p in on_disk['points']] == [1, 3, 5]
    for p in on_disk['points']:                                 # the finished points are right
        _, h = sps.dfreqresp(sys_, w=[2 * np.pi * p['freq_hz'] * 1e-3])
        assert p['gain_db'] == pytest.approx(20 * np.log10(abs(h[0])), abs=0.05)
        assert p['phase_deg'] == pytest.approx(np.degrees(np.angle(h[0])), abs=0.5)
    assert summary['points'] == on_disk['points']
    assert len(os.listdir(tmp_path / 'data')) == 3             # one raw file per finished point
    assert (tmp_path / 'data.csv').exists() and (tmp_path / 'bode.png').exists()


def test_main_job_batch_mode(tmp_path):
    res = subprocess.run([RUN, '--mode', 'batch', '--out', str(tmp_path), '--name', 'b',
                          '--start-hz', '2', '--step-hz', '4', '--max-hz', '14', '--periods', '5'],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    summary = json.load(open(tmp_path / 'b' / 'summary.json'))
    assert summary['complete'] and len(summary['points']) == 4
    assert summary['bandwidth_hz'] is None or summary['bandwidth_hz'] >= 7.0
    assert all(p['coherence'] > 0.9 for p in summary['points'] if p['freq_hz'] < 10)
    assert 'bandwidth (-3 dB)' in res.stdout and f'report: {tmp_path}/b/' in res.stdout


@pytest.mark.parametrize('args, words', [
    (['--max-hz', '80'], 'above Nyquist/10'),
    (['--amplitude-mm', '70'], 'beyond the stroke'),
    (['--periods', '-3'], 'periods -3'),
])
def test_bad_sweep_options_one_line(args, words, tmp_path):
    res = subprocess.run([RUN, '--mode', 'batch', '--out', str(tmp_path)] + args,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and 'Traceback' not in res.stderr, res.stderr
    assert not os.listdir(tmp_path), 'nothing is written for a refused sweep'
