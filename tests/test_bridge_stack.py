"""The sim/real swap: the same estimator, controller and sweep run once on plant_sim and once
on hardware_bridge + the ADS test peer (scripts/ads_peer --lockstep, plant behind real ADS
traffic), both in lock-step so the figures measure the loop, not the machine. A 5 mm step
and a short stepped sweep (measured position) must agree within 0.5 dB / 5 degrees."""
import json
import subprocess
import threading

import numpy as np
import pytest

from eha_ros.core.io import recording
from eha_ros.stack import Stack, node_command
from ros_util import ROOT, start_process, stop_process, wait_for
from test_bridge_core import free_port

pytestmark = pytest.mark.ros
COMMON = ['-p', 'use_sim_time:=true', '-p', 'sweep:sweep.output:=measured',
          '-p', 'sweep:sweep.start_delay:=0.3']
STEP = ['-p', 'sweep:sweep.mode:=step', '-p', 'sweep:sweep.amplitude:=0.005',
        '-p', 'sweep:sweep.step_duration:=1.0']
SWEEP = ['-p', 'sweep:sweep.start_hz:=2.0', '-p', 'sweep:sweep.increment_hz:=3.0',
         '-p', 'sweep:sweep.max_hz:=11.0', '-p', 'sweep:sweep.periods:=4',
         '-p', 'sweep:sweep.settle_periods:=1', '-p', 'sweep:sweep.relax_s:=0.1']


def run_sweep(out, name, extra):
    cmd = node_command('sweep', extra=COMMON + extra + ['-p', f'sweep:sweep.out_dir:={out}',
                                                        '-p', f'sweep:sweep.run_name:={name}'])
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=240)
    assert res.returncode == 0, res.stderr[-2000:]
    return out / name


def step_figures(folder, freqs=(1.0, 2.0, 3.0, 4.0, 5.0)) -> dict:
    """Overshoot, steady error, and the closed-loop response from the step in dB/degrees:
    H(f) = DTFT(diff x) / DTFT(diff reference) over 1 s from just before the step."""
    data = np.genfromtxt(folder / 'data.csv', delimiter=',', names=True)
    ref, x = data['reference'], data['measured']
    k0 = int(np.argmax(ref > 0.0025))
    xs = np.convolve(x, np.ones(5) / 5, mode='same')[k0 - 50:k0 + 950]
    xs = xs - np.mean(xs[:50])
    dx, dr = np.diff(x[k0 - 20:k0 + 980]), np.diff(ref[k0 - 20:k0 + 980])
    e = np.exp(-2j * np.pi * np.outer(freqs, np.arange(len(dx))) * 1e-3)
    h = (e @ dx) / (e @ dr)
    return {'overshoot_pct': 100 * (xs.max() - 0.005) / 0.005,
            'final_error_um': 1e6 * (np.mean(xs[-300:]) - 0.005),
            'freqs': freqs, 'gain_db': 20 * np.log10(np.abs(h)),
            'phase_deg': np.degrees(np.angle(h))}


def arm_bridge(node):
    from std_srvs.srv import SetBool
    cli = node.create_client(SetBool, '/eha/bridge/arm')
    assert cli.wait_for_service(timeout_sec=30)
    for _ in range(20):                       # the controller may still be settling
        fut = cli.call_async(SetBool.Request(data=True))
        assert wait_for(fut.done, 20)
        if fut.result().success:
            return
        wait_for(lambda: False, 0.5)
    raise AssertionError(f'bridge not armed: {fut.result().message}')


def run_case(plant, tmp, ros_node):
    peer = None
    extra = {}
    if plant == 'hardware_bridge':
        port = free_port()
        peer = start_process([f'{ROOT}/scripts/ads_peer', '--lockstep', '--no-ros',
                              '--port', str(port)])
        lines = []
        threading.Thread(target=lambda: lines.append(peer.stdout.readline()), daemon=True).start()
        assert wait_for(lambda: lines and 'serving' in lines[0], 60), lines
        extra = {plant: ['-p', f'hardware_bridge:ads.tcp_port:={port}',
                         '-p', 'hardware_bridge:bridge.startup_discovery:=0.5']}
    rec = str(tmp / f'{plant}.mcap')        # lock-step + recording: tick 0 waits for it
    st = Stack([plant, 'estimator', 'controller'], lockstep=True, extra=extra, record=rec).start()
    try:
        if peer is not None:
            arm_bridge(ros_node)
        step = step_figures(run_sweep(tmp, f'{plant}_step', STEP))
        summary = json.load(open(run_sweep(tmp, f'{plant}_sweep', SWEEP) / 'summary.json'))
    finally:
        res = st.stop()
        for name, (code, err) in res.items():
            assert 'Traceback' not in err, (name, err)
        if peer is not None:
            code, out, err = stop_process(peer)
            assert 'Traceback' not in err, err
    assert 'start gate: recorder subscribed to every /eha/* topic' in res[plant][1]
    # the plant side's own stream is recorded from the first ticks (the start gate)
    (_, first), = recording.read(rec, ['/eha/state'])['/eha/state'][:1]
    assert first.seq < 50, (plant, first.seq)
    return step, summary


@pytest.fixture(scope='module')
def results(tmp_path_factory, rclpy_session):
    from ros_util import Spinner
    node = rclpy_session.create_node('bridge_stack_test')
    spinner = Spinner(node)
    tmp = tmp_path_factory.mktemp('swap')
    try:
        yield {p: run_case(p, tmp, node) for p in ('plant_sim', 'hardware_bridge')}
    finally:
        spinner.close()
        node.destroy_node()


def test_5mm_step_same_as_plant_sim(results):
    sim, ads = results['plant_sim'][0], results['hardware_bridge'][0]
    for name, r in (('plant_sim', sim), ('bridge+ADS', ads)):
        print(f'5 mm step, {name}: overshoot {r["overshoot_pct"]:.2f} %, steady error '
              f'{r["final_error_um"]:.1f} um (measured position)')
    for f, g0, p0, g1, p1 in zip(sim['freqs'], sim['gain_db'], sim['phase_deg'], ads['gain_db'],
                                 ads['phase_deg']):
        print(f'step response at {f:.0f} Hz: plant_sim {g0:6.2f} dB {p0:7.1f} deg | bridge+ADS '
              f'{g1:6.2f} dB {p1:7.1f} deg | diff {g1 - g0:+.3f} dB {p1 - p0:+.2f} deg')
        assert abs(g1 - g0) <= 0.5 and abs(p1 - p0) <= 5.0
    # plant_sim alone scatters by 1.6 points of overshoot between runs (noise, friction);
    # with the controller's acceleration-limited step both stay within issue 6's 5 %
    assert abs(sim['overshoot_pct'] - ads['overshoot_pct']) < 3.0
    assert ads['overshoot_pct'] < 5.0 and sim['overshoot_pct'] < 5.0


def test_stepped_sweep_same_as_plant_sim(results):
    sim, ads = results['plant_sim'][1], results['hardware_bridge'][1]
    assert sim['complete'] and ads['complete']
    assert [p['freq_hz'] for p in sim['points']] == [p['freq_hz'] for p in ads['points']] == \
        [2, 5, 8, 11]
    for a, b in zip(sim['points'], ads['points']):
        dg, dp = b['gain_db'] - a['gain_db'], b['phase_deg'] - a['phase_deg']
        print(f'{a["freq_hz"]:5.1f} Hz: plant_sim {a["gain_db"]:6.2f} dB {a["phase_deg"]:7.1f} deg'
              f' | bridge+ADS {b["gain_db"]:6.2f} dB {b["phase_deg"]:7.1f} deg | '
              f'diff {dg:+.3f} dB {dp:+.2f} deg')
        assert abs(dg) <= 0.5 and abs(dp) <= 5.0
    print(f'bandwidth plant_sim {sim["bandwidth_hz"]} Hz, bridge {ads["bandwidth_hz"]} Hz; phase '
          f'at 7 Hz {sim["phase_at_7hz_deg"]} vs {ads["phase_at_7hz_deg"]} deg')
