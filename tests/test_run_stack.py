"""scripts/run_stack as a user runs it: a run folder with logs and stack.json, clean exits,
one-line errors, a dead node reported. In a module of its own: it owns the /eha topics."""
import json
import os
import subprocess

import pytest

from ros_util import ROOT

pytestmark = pytest.mark.ros


def run_stack(tmp_path, *args, timeout=180):
    r = subprocess.run([os.path.join(ROOT, 'scripts', 'run_stack'), '--out', str(tmp_path),
                        '--name', 'run', '--progress', '2', *args],
                       capture_output=True, text=True, timeout=timeout)
    folder = tmp_path / 'run'
    summary = json.loads((folder / 'stack.json').read_text()) \
        if (folder / 'stack.json').exists() else None
    return r, folder, summary


@pytest.mark.parametrize('mode, procs', [
    ('realtime', {'eha_loop'}),
    ('lockstep', {'plant_sim', 'estimator', 'controller', 'switch_manager'})])
def test_runs_for_duration_and_stops_cleanly(tmp_path, mode, procs):
    r, folder, summary = run_stack(tmp_path, '--mode', mode, '--duration', '12')
    assert r.returncode == 0, r.stdout[-1500:] + r.stderr[-1500:]
    assert 'all processes exited cleanly' in r.stdout
    assert set(summary['exit_codes']) == procs and set(summary['exit_codes'].values()) == {0}
    for p in procs:
        assert (folder / 'logs' / f'{p}.log').exists()
    loop = summary['diagnostics']['plant_sim: loop']
    assert loop['ticks'] > 500                 # the loop ran (lock-step: as fast as DDS allows)
    assert summary['stop_reason'] == 'duration' and summary['wall_s'] >= 12
    assert set(summary['cpu_share']) == procs
    for node in ('estimator', 'controller', 'switch_manager'):
        assert any(k.startswith(node) for k in summary['diagnostics']), node


def test_a_node_that_dies_is_reported(tmp_path):
    r, folder, summary = run_stack(tmp_path, '--structure', 'processes', '--duration', '30',
                                   '-p', 'controller:control.rate_limit:=-1')
    assert r.returncode == 1
    assert summary['stop_reason'] == 'node exited: controller (2)'
    assert 'control.rate_limit' in r.stderr and 'Traceback' not in r.stderr + r.stdout


@pytest.mark.parametrize('args, expect', [
    (['-p', 'bogus:key:=1'], "node 'bogus' is not in this stack"),
    (['-p', 'plant_sim:no_separator'], 'expected node:key:=value'),
    (['--mode', 'lockstep', '--structure', 'composed'], 'real time only'),
    (['--duration', '-1'], 'must be positive'),
    (['--no-peer'], 'only applies to --plant bridge'),
])
def test_bad_options_are_one_line(tmp_path, args, expect):
    r, folder, summary = run_stack(tmp_path, *args, timeout=60)
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if not ln.startswith('setup:')]
    assert len(lines) == 1 and expect in lines[0], r.stderr
    assert summary is None


def test_plant_swapped_for_the_bridge_and_the_ads_test_peer(tmp_path):
    """--plant bridge changes only the plant side: ads_peer (the simulated PLC) + the bridge in
    place of plant_sim, armed at start because the PLC is the simulated one."""
    r, folder, summary = run_stack(tmp_path, '--plant', 'bridge', '--duration', '6')
    assert r.returncode == 0, r.stdout[-1500:] + r.stderr[-1500:]
    assert set(summary['exit_codes']) == {'ads_peer', 'eha_loop'}
    assert '--plant bridge' in summary['processes']['eha_loop']
    link = summary['diagnostics']['hardware_bridge: link']
    assert link['armed'] is True and link['link_up'] is True and link['ticks'] > 100, link
    assert 'plant_sim: loop' not in summary['diagnostics']
    for node in ('estimator', 'controller', 'switch_manager'):
        assert any(k.startswith(node) for k in summary['diagnostics']), node
