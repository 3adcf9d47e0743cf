"""Redundancy switch manager core (thesis 3.4, Fig. 3.12, Table 3.4), batch, no DDS:
debounce/hysteresis, the state machine and its valve sequence, commanded switch in the Table 3.4
scenario, motor_fail automatic switch, 60 s without a false alarm, both failed -> safe state."""
import collections
import json
import math
import os
import re
import subprocess

import numpy as np
import pytest

from eha_ros.core.config.params import ParamError
from eha_ros.core.redundancy import ChannelSample, Hysteresis, Select, SwitchManager
from eha_ros.core.sim import switchover as B
from eha_ros.core.redundancy.events import EventLog, read_log
from eha_ros.core.redundancy.params import check
from eha_ros.stack import node_command
from eha_ros.tools.plot_switch import plot_switches, read_csv, write_csv

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, 'out', 'redundancy', 'batch')
T_SWITCH = 3.0
PERIOD = 1.0 / 3.0
# The controller's hold on a switch (control.switch_hold) freezes G's state and so opens the
# position loop for its duration. With the pre-spun valve cross-over the flow hand-over needs
# no hold, so the figures are measured with it off (see the test that measures it with the
# hold on: 0.013 mm against 0.010 mm extra deviation with the stack's controller).
HOLD = 0.0


def fig_line(name, fig):
    os.makedirs(OUT, exist_ok=True)
    slug = re.sub(r'[^a-z0-9]+', '_', name.lower()).strip('_')
    with open(os.path.join(OUT, f'{slug}.json'), 'w') as fh:
        json.dump({'scenario': name, **fig}, fh, indent=1)
    print(f'{name}: ' + ', '.join(f'{k} = {v * 1e3:.3f} m{"m" if k.endswith("_m") else "s"}'
                                  for k, v in fig.items()))


# --------------------------------------------------------------------------- debounce
def test_hysteresis_debounce_and_clear_level():
    h = Hysteresis(trip=10.0, clear=5.0, trip_time=0.005, clear_time=0.02)
    t = 0.0
    for _ in range(5):            # 5 samples over trip = 4 ms < 5 ms: still healthy
        assert h.update(t, 11.0)
        t += 1e-3
    assert h.update(t, 4.0)       # spike ended: timer reset
    for k in range(6):
        t += 1e-3
        ok = h.update(t, 11.0)
    assert not ok                 # 6 samples = 5 ms over trip
    for _ in range(100):          # between clear and trip: stays unhealthy (hysteresis)
        t += 1e-3
        assert not h.update(t, 7.0)
    for k in range(20):
        t += 1e-3
        assert not h.update(t, 4.0)
    t += 1e-3
    assert h.update(t, 4.0)       # below clear for 20 ms
    assert h.update(t + 1e-3, float('nan'))     # non-finite level: verdict held
    with pytest.raises(ValueError):
        Hysteresis(1.0, 2.0, 0.0, 0.0)


# --------------------------------------------------------------------------- state machine
@pytest.fixture
def params():
    return B.switch_params()


def sample(t, fault=(False, False), enabled=(True, False), w=(100.0, 0.0), ref=100.0,
           i=(1.0, 0.0)):
    return ChannelSample(t, ref, w, i, 3e6, 1e6, enabled, fault, True, 1e-5, True)


class Bench:
    """Feeds the manager samples whose drive enables follow its select (like the plant)."""

    def __init__(self, params, spin=math.inf, **over):
        """spin: how fast (rad/s per tick) an enabled motor reaches 100 rad/s and a disabled
        one stops (inf: at once)."""
        params = dict(params, **over)
        self.m = SwitchManager(params)
        self.k = 0
        self.fault = [False, False]
        self.log = []
        self.spin, self.w = spin, [100.0, 0.0]

    def tick(self, n=1, **kw):
        for _ in range(n):
            sel = self.m.select
            for c in range(2):
                dw = (100.0 if sel.drive_enable[c] else 0.0) - self.w[c]
                self.w[c] += max(-self.spin, min(self.spin, dw))
            self.m.update(sample(self.k * 1e-3, tuple(self.fault), sel.drive_enable,
                                 tuple(self.w)), self.k)
            self.log.append((self.k * 1e-3, self.m.name, self.m.select))
            self.k += 1

    def when(self, pred):
        return [t for t, name, sel in self.log if pred(name, sel)]


# sample modifications making the active couple A look sick to one monitor each
SICK = {
    'speed': dict(w=-200.0),                    # 300 rad/s off its 100 rad/s reference
    'current': dict(i=35.0),                    # 0.97 I_max (p_D consistent with it)
    'pressure': dict(i=10.0, p_d=20e5),         # 10 A (= 109 bar of torque) but p_D 20 bar
    'estimator': dict(innovation=2e-3),         # 2 mm position innovation
}


@pytest.mark.parametrize('monitor', sorted(SICK))
def test_each_monitor_trips_automatic_switch(params, monitor):
    m = SwitchManager(params)
    k_T, D_p = params['plant.motor.k_T'], params['plant.pump.D_p']
    for k in range(1000):
        sig = dict(w=100.0, i=1.0, innovation=1e-5)
        if k >= 300 and m.active == 0:
            sig.update(SICK[monitor])
        p_d = sig.get('p_d', k_T * sig['i'] / D_p)       # torque balance of eq. 3.17
        a, sel = m.active, m.select
        w = tuple(sig['w'] if c == a else 0.0 for c in range(2))
        i = tuple(sig['i'] if c == a else 0.0 for c in range(2))
        m.update(ChannelSample(k * 1e-3, 100.0, w, i, 1e6 + p_d, 1e6, sel.drive_enable,
                               (False, False), True, sig['innovation'], True), k)
    ev = m.events[0]
    print(f'{monitor}: switch after {(ev.t - 0.3) * 1e3:.0f} ms: {ev.reason}')
    assert ev.kind == 'switch_start' and ev.reason.startswith(f'channel A unhealthy: {monitor}')
    trip_time = params[f'switch.health.{monitor}.trip_time']
    assert trip_time - 1e-3 <= ev.t - 0.3 <= trip_time + 0.06       # debounce (+ filter lag)
    assert m.name == 'DEGRADED' and m.active == 1 and len(m.events) == 2


def test_loop_not_closed_holds_loop_monitors(params):
    """Start-up or starved stack (commands stale): no speed/current verdict, drive still."""
    m = SwitchManager(params)
    for k in range(500):
        s = ChannelSample(k * 1e-3, 800.0, (-500.0, 0.0), (35.0, 0.0), 3e6, 1e6, (True, False),
                          (False, False), True, 5e-3, True, loop_ok=False)
        m.update(s, k)
    assert m.events == [] and m.name == 'ACTIVE_A'
    s.drive_fault = (True, False)
    for k in range(500, 510):
        s.t = k * 1e-3
        m.update(s, k)
    assert m.events and 'drive' in m.events[0].reason


@pytest.mark.parametrize('spin, over, opens', [
    (10.0, {}, 8e-3),                 # B within prespin_match (20 rad/s) of A after 8 ms
    (1.0, {}, None),                  # B too slow to match: the valves open at prespin_time
    (math.inf, {'switch.prespin_match': 0.0}, None)])   # matching off: prespin_time
def test_commanded_switch_valve_sequence_and_timing(params, spin, over, opens):
    """The pre-spin ends when the new motor's speed matches the old one's (the flow is handed
    over at one speed: the estimator's model input, the active couple's speed, stays the
    pump's), at the latest after prespin_time; then the valves change over together."""
    b = Bench(params, spin, **over)
    b.tick(100)
    assert b.m.name == 'ACTIVE_A' and b.m.select == Select.only(0)
    ok, msg = b.m.request(1, 'test')
    assert ok, msg
    t0 = b.k * 1e-3 - 1e-3
    b.tick(100)
    pre, vt, margin = (params['switch.prespin_time'], params['plant.valves.onoff_time'],
                       params['switch.valve_margin'])
    pre = pre if opens is None else opens
    # 1) new drive on with its valves closed (pre-spin), old couple still driving
    spin = b.when(lambda n, s: s.drive_enable == (True, True) and s.valve_open == (True, False))
    assert spin and abs(spin[0] - t0) < 1.5e-3 and abs(len(spin) * 1e-3 - pre) < 1.5e-3
    # 2) cross-over: new valves open, old valves close together, channel = B
    cross = b.when(lambda n, s: s.drive_enable == (True, True) and s.valve_open == (False, True))
    assert cross and s_close(cross[0] - t0, pre) and s_close(len(cross) * 1e-3, vt + margin)
    assert all(s.channel == 1 for t, n, s in b.log if t in cross)
    # 3) old drive off: complete, ACTIVE_B
    assert b.m.name == 'ACTIVE_B' and b.m.select == Select.only(1) and b.m.switch_count == 1
    assert {n for t, n, s in b.log if t0 < t < t0 + pre + vt + margin - 1e-3} == {"SWITCHING"}
    kinds = [e.kind for e in b.m.events]
    assert kinds == ['switch_start', 'switch_done']
    assert b.m.events[0].commanded and 'test' in b.m.events[0].reason
    assert f'valves opened after {pre * 1e3:.0f} ms' in b.m.events[1].reason
    assert set(b.m.events[0].health) == {'A', 'B'}


def s_close(a, b, tol=1.5e-3):
    return abs(a - b) < tol


def test_requests_refused_with_reason(params):
    b = Bench(params)
    b.tick(10)
    assert b.m.request(0, 'x') == (True, 'channel A is already active (ACTIVE_A)')
    ok, msg = b.m.request(2, 'x')
    assert not ok and 'expected 0 (A) or 1 (B)' in msg
    b.fault[1] = True
    b.tick(10)
    ok, msg = b.m.request(1, 'x')
    assert not ok and 'drive' in msg and b.m.name == 'DEGRADED'
    b.fault[1] = False
    b.tick(600)                              # clear_time 0.5 s: healthy again
    assert b.m.name == 'ACTIVE_A'
    assert b.m.request(1, 'x')[0]
    ok, msg = b.m.request(0, 'y')
    assert not ok and 'in progress' in msg
    assert [e.kind for e in b.m.events] == ['degraded', 'refused', 'restored', 'switch_start',
                                            'refused']


def test_drive_fault_automatic_switch_isolates_at_once(params):
    b = Bench(params)
    b.tick(100)
    b.fault[0] = True
    t_fault = b.k * 1e-3
    b.tick(100)
    start = b.m.events[0]
    assert start.kind == 'switch_start' and not start.commanded and 'drive' in start.reason
    # debounce 2 ms: third faulty sample
    assert s_close(start.t - t_fault, params['switch.health.drive.trip_time'])
    first = b.when(lambda n, s: s.channel == 1)[0]
    assert first == pytest.approx(start.t)                # no pre-spin for a fault
    sel = [s for t, n, s in b.log if t == first][0]
    assert sel.drive_enable == (False, True) and sel.valve_open == (False, True)
    assert b.m.name == 'DEGRADED' and b.m.channel_healthy == [False, True]
    # A latched failed even when its fault clears: no automatic switch back
    b.fault[0] = False
    b.tick(1000)
    assert b.m.name == 'DEGRADED' and b.m.switch_count == 1
    assert 'latched' in b.m._why_not(0)
    assert b.m.request(0, 'retry after repair')[0]       # commanded retry is allowed
    b.tick(100)
    assert b.m.name == 'ACTIVE_A'


@pytest.mark.parametrize('mode', ['hold', 'bypass'])
def test_both_failed_safe_state_latched_no_oscillation(params, mode):
    b = Bench(params, **{'switch.safe_mode': mode})
    b.tick(100)
    b.fault[0] = True
    b.tick(600)
    b.fault[1] = True
    b.tick(50)
    assert b.m.name == 'FAILED_SAFE'
    safe = Select(1, (False, False), (False, False), mode == 'bypass')
    assert b.m.select == safe
    # faults come and go: the safe state holds, no switching between two failed couples
    for k in range(6):
        b.fault = [k % 2 == 0, k % 2 == 1]
        b.tick(700)
    assert b.m.name == 'FAILED_SAFE' and b.m.select == safe and b.m.switch_count == 1
    assert [e.kind for e in b.m.events] == ['switch_start', 'switch_done', 'safe']
    assert mode in b.m.events[-1].reason


def _pressure_run(params, residual_b):
    """A drives with 10 A (109 bar of torque) and the measured p_D 89 bar off that from 0.3 s
    (residual -89 bar: what a sensor offset of +89 bar does); after the automatic switch B
    drives with residual ``residual_b`` (Pa)."""
    m = SwitchManager(params)
    k_T, D_p = params['plant.motor.k_T'], params['plant.pump.D_p']
    torque = k_T * 10.0 / D_p
    for k in range(1500):
        a = m.active
        off = 0.0 if k < 300 else (-89e5 if a == 0 else residual_b)
        w = tuple(100.0 if c == a else 0.0 for c in range(2))
        i = tuple(10.0 if c == a else 0.0 for c in range(2))
        m.update(ChannelSample(k * 1e-3, 100.0, w, i, 1e6 + torque - off, 1e6,
                               m.select.drive_enable, (False, False), True, 1e-5, True), k)
    return m


def test_pressure_sensor_fault_is_not_two_couple_faults(params):
    """The residual that switched A out comes back on B: the pressure sensors both share are
    wrong, not both couples. B keeps driving, A is available again, the pressure monitor is off
    and reported; no safe state."""
    m = _pressure_run(params, -89e5)
    kinds = [e.kind for e in m.events]
    print(kinds, m.events[-1].reason)
    assert kinds == ['switch_start', 'switch_done', 'sensor_fault']
    assert m.events[0].reason.startswith('channel A unhealthy: pressure')
    assert 'pressure sensors' in m.events[-1].reason and m.pressure_sensor_fault
    assert m.name == 'ACTIVE_B' and m.channel_healthy == [True, True] and m.switch_count == 1
    assert m.health.failed(0) == m.health.failed(1) == []


@pytest.mark.parametrize('residual_b', [89e5, -200e5])
def test_unlike_pressure_residuals_are_two_couple_faults(params, residual_b):
    """A residual of the other sign, or more than twice the first, on B: two couple faults,
    the safe state as before."""
    m = _pressure_run(params, residual_b)
    assert [e.kind for e in m.events] == ['switch_start', 'switch_done', 'safe']
    assert m.name == 'FAILED_SAFE' and not m.pressure_sensor_fault


def test_target_failing_during_switch_goes_back_once(params):
    b = Bench(params)
    b.tick(100)
    assert b.m.request(1, 'x')[0]
    b.tick(5)
    b.fault[1] = True
    b.tick(200)
    assert b.m.name == 'DEGRADED' and b.m.active == 0 and b.m.switch_count == 2
    assert b.m.select == Select.only(0)


def test_params_cross_checks_one_line(params):
    bad = dict(params, **{'switch.health.speed.clear': 500.0})
    with pytest.raises(ParamError, match=r'^switch.health.speed.clear = 500.0: expected <= '):
        check(bad)
    with pytest.raises(ParamError, match='safe_mode'):
        B.switch_params({'switch.safe_mode': 'panic'})


def test_bad_parameter_stops_node_with_one_line():
    cmd = node_command('switch_manager', extra=('-p', 'switch_manager:switch.min_dwell:=-1.0'))
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert lines == [lines[-1]] and 'switch.min_dwell = -1.0: expected float in [0, 60] s' \
        in lines[0], res.stderr


def test_event_log_json_lines(tmp_path, params):
    b = Bench(params)
    b.tick(10)
    b.m.request(1, 'log me')
    b.tick(100)
    log = EventLog(str(tmp_path / 'run'))
    for ev in b.m.events:
        log.append(ev)
    recs = read_log(log.path)
    assert [r['kind'] for r in recs] == ['switch_start', 'switch_done']
    assert {'t', 'from_state', 'to_state', 'reason', 'health'} <= set(recs[0])
    assert recs[0]['health']['A']['speed']['healthy'] is True


# --------------------------------------------------------------------------- closed loop
@pytest.fixture(scope='module')
def runs():
    scn = dict(duration=3.6)
    out = {'ref': B.run(B.Scenario(**scn), switch_hold=HOLD),
           'switch': B.run(B.Scenario(**scn, commands=[(T_SWITCH, 1, 'Table 3.4')]),
                           switch_hold=HOLD),
           'fail': B.run(B.Scenario(**scn, faults=[(T_SWITCH, 'motor_fail', 0, 0.0, 0.0)]),
                         switch_hold=HOLD)}
    return out


def recording(r):
    return {'t': r['t'], 'ref': r['ref'], 'x': r['x'], 'w0': r['w'][0], 'w1': r['w'][1],
            'w_ref': r['w_ref'], 'valve0': r['valve'][0], 'valve1': r['valve'][1],
            'bypass': r['bypass'], 'active': r['active']}


def test_table_3_4_commanded_switch(runs):
    sw, ref = runs['switch'], runs['ref']
    assert [e.kind for e in ref['manager'].events] == [], 'switch without cause'
    ev = sw['manager'].events
    assert [e.kind for e in ev] == ['switch_start', 'switch_done'] and ev[0].commanded
    fig = B.tracking_figures(sw['t'], sw['x'], sw['ref'], T_SWITCH, PERIOD)
    twin = float(np.max(np.abs(sw['x'] - ref['x'])[sw['t'] > T_SWITCH]))
    fig_line('Table 3.4 commanded switch (batch)', dict(fig, twin_extra_deviation_m=twin))
    print(f'estimator in the loop: {sw["estimator"]}')
    assert twin <= 1e-3 and fig['extra_deviation_m'] <= 1e-3
    assert fig['recovery_time_s'] <= 0.05
    # B drives afterwards, A stopped
    late = sw['t'] > T_SWITCH + 0.1
    assert np.all(sw['active'][late] == 1) and np.all(sw['i'][0][late] == 0.0)
    assert np.abs(sw['w'][1][late]).max() > 50.0


def test_motor_fail_automatic_switch(runs):
    r, ref = runs['fail'], runs['ref']
    ev = r['manager'].events
    assert ev[0].kind == 'switch_start' and not ev[0].commanded and 'drive' in ev[0].reason
    t_drive = B.driving_time(r['t'], r['valve'], r['enable'], 1, T_SWITCH)
    fig = B.tracking_figures(r['t'], r['x'], r['ref'], T_SWITCH, PERIOD)
    twin = float(np.max(np.abs(r['x'] - ref['x'])[r['t'] > T_SWITCH]))
    fig_line('motor_fail on A (batch)', dict(fig, twin_extra_deviation_m=twin,
                                              fault_to_B_driving_s=t_drive,
                                              detection_s=ev[0].t - T_SWITCH))
    assert t_drive <= 0.1
    assert twin <= 3e-3 and fig['extra_deviation_m'] <= 3e-3
    assert r['manager'].name == 'DEGRADED' and r['manager'].channel_healthy == [False, True]


def test_switch_plots(runs, tmp_path):
    os.makedirs(OUT, exist_ok=True)
    paths = []
    for name in ('switch', 'fail'):
        rec = recording(runs[name])
        csv_path = os.path.join(OUT, f'{name}.csv')
        write_csv(csv_path, rec)
        back = read_csv(csv_path)
        assert np.allclose(back['x'], rec['x'], atol=1e-9)
        paths += plot_switches(back, [T_SWITCH], os.path.join(OUT, name),
                               labels=[f'batch {name} at {T_SWITCH} s'])
    assert len(paths) == 2 and all(os.path.getsize(p) > 10000 for p in paths)
    print('plots: ' + ', '.join(os.path.relpath(p, ROOT) for p in paths))


# the leakiest corner of Table 4.5 (family row 226): the pump runs near omega_max under the
# 10 kN load, so a new motor spun up for a fixed 10 ms was at about half the old one's speed
LEAKY = {'C_eq': 10.0, 'D_p': 0.8, 'beta': 0.99, 'k_T': 0.8, 'k_E': 0.98}


def test_speed_matched_hand_over_on_the_leaky_corner():
    """A commanded switch opens the new couple's valves once its speed matches the old one's.
    With the old fixed 10 ms pre-spin the new motor was at about half the speed when its
    valves opened: the estimator's model input (the active couple's speed) dropped, the
    estimate fell 0.25 mm behind, the command saturated, and the switch added 0.19-0.28 mm
    (Table 3.4 scenario, three noise seeds). Matched: at most 0.1 mm, and with the leakage
    compensation on the error is back in its band within the 50 ms."""
    from eha_ros.core.sim import campaign, scenarios as S
    scn = S.load('switch')
    for seed in (1, 2, 3):
        out = {}
        for name, node, over in (
                ('matched', 'switch_manager', {}),
                ('fixed 10 ms', 'switch_manager', {'switch.prespin_match': 0.0,
                                                   'switch.prespin_time': 0.01}),
                ('compensated', 'controller', {'control.leakage_compensation': 1.0})):
            nom = campaign.nominal_params()
            nom[node].update(over)
            out[name], _ = S.run(scn, nom, LEAKY, seed, trace=False)
        print(f'seed {seed}: ' + ', '.join(f'{n} extra {f["extra_deviation_m"] * 1e3:.3f} mm '
                                           f'recovery {f["recovery_time_s"]:.3f} s drive '
                                           f'{f["drive_time_s"] * 1e3:.0f} ms'
                                           for n, f in out.items()))
        assert out['fixed 10 ms']['extra_deviation_m'] > 1.5e-4
        for name in ('matched', 'compensated'):
            f = out[name]
            assert f['extra_deviation_m'] <= 1e-4 and f['recovery_time_s'] <= 0.05
            assert f['drive_time_s'] <= 0.1 and f['final_channel'] == 1


def test_controller_integrator_hold_costs_deviation(runs):
    """Measured, not a spec: a 20 ms control.switch_hold (G's state frozen; the default is 0) on
    the same switch costs deviation against the twin run without a switch."""
    held = B.run(B.Scenario(duration=3.4, commands=[(T_SWITCH, 1, 'Table 3.4')]), switch_hold=0.02)
    fig = B.tracking_figures(held['t'], held['x'], held['ref'], T_SWITCH, PERIOD)
    twin = float(np.max(np.abs(held['x'] - runs['ref']['x'][:len(held['x'])])[
        held['t'] > T_SWITCH]))
    fig_line('Table 3.4 commanded switch, controller hold 20 ms',
             dict(fig, twin_extra_deviation_m=twin))
    no_hold = float(np.max(np.abs(runs['switch']['x'] - runs['ref']['x'])[
        runs['switch']['t'] > T_SWITCH]))
    assert twin >= no_hold


def test_nominal_60_s_no_false_alarm():
    r = B.run(B.Scenario(duration=60.0, seed=3))
    m = r['manager']
    levels = {c: {n: h for n, h in m.health.channels[c].monitors.items()} for c in (0, 1)}
    print(f'60 s nominal: events {len(m.events)}, switch_count {m.switch_count}, '
          f'estimator {r["estimator"]}')
    assert m.events == [] and m.switch_count == 0 and m.name == 'ACTIVE_A'
    assert np.all(r['state'] == 0)
    assert all(h.healthy for c in (0, 1) for h in levels[c].values())


def test_both_failed_in_loop_safe_state_holds_piston():
    scn = B.Scenario(duration=4.0, faults=[(1.5, 'motor_fail', 0, 0.0, 0.0),
                                           (2.5, 'motor_fail', 1, 0.0, 0.0)])
    r = B.run(scn, switch_hold=HOLD)
    m = r['manager']
    kinds = [e.kind for e in m.events]
    print(f'both failed: events {kinds}, state {m.name}')
    assert kinds == ['switch_start', 'switch_done', 'safe']
    safe_t = m.events[-1].t
    assert 2.5 < safe_t < 2.52
    after = r['t'] > safe_t + 0.05
    assert np.all(r['state'][after] == B.STATE_CODES['FAILED_SAFE'])
    assert np.all(r['valve'][:, after] == 0.0) and not r['enable'][:, after].any()
    # hold: hydraulic lock under 10 kN, the piston creeps by leakage only
    x = r['x'][after]
    print(f'hold: piston moved {1e3 * (x[-1] - x[0]):.3f} mm in {r["t"][after][-1] - safe_t:.2f} s')
    assert abs(x[-1] - x[0]) < 2e-3


def test_one_pressure_sensor_offset_in_loop_keeps_control():
    """Closed loop, Table 3.4 (3 Hz 3 mm sine, 10 kN from 1 s): chamber A's pressure sensor
    reads 100 bar high from 1.5 s. The torque balance switches A out, B shows the same
    residual, the manager blames the sensors: B keeps driving, the piston keeps tracking."""
    scn = B.Scenario(duration=4.0, faults=[(1.5, 'pressure_sensor_a', 0, 100e5, 0.0)])
    r = B.run(scn, switch_hold=HOLD)
    m = r['manager']
    kinds = [e.kind for e in m.events]
    err = r['x'] - np.array([scn.reference(t) for t in r['t']])
    after = r['t'] > 1.5
    before = np.abs(err[~after & (r['t'] > 1.2)]).max()      # loaded, the sine's own lag
    worst = np.abs(err[after]).max()
    print(f'pressure sensor A +100 bar: events {kinds}, state {m.name}, max |error| after '
          f'{1e6 * worst:.0f} um (before {1e6 * before:.0f})')
    assert kinds == ['switch_start', 'switch_done', 'sensor_fault'] and m.name == 'ACTIVE_B'
    assert not np.any(r['state'] == B.STATE_CODES['FAILED_SAFE'])
    assert worst < 1.1 * before


def test_pressure_sensors_blamed_stop_the_leakage_compensation():
    """pressure_fault (chamber A's sensor 100 bar high from 2 s, Table 3.4 under 10 kN) on the
    softest corner of Table 4.5 with the compensation at alpha 0.5: once the manager blames the
    sensors, the controller stops adding the leak flow of the wrong p_D and the estimator
    stops reading them (as their nodes do on /eha/redundancy). Kept on, the compensation
    holds the piston 0.3 mm off its reference on average (tuning seed 1)."""
    from eha_ros.core.sim import campaign
    from eha_ros.core.sim import closed_loop as CL
    from eha_ros.core.sim import scenarios as SC
    from eha_ros.core.sim.batch import build_loop, nominal_params
    from eha_ros.core.sim.family import COLUMNS, plant_params
    from eha_ros.core.sim.switchover import schedule
    scn = SC.load('pressure_fault')
    mult = dict({c: 1.0 for c in COLUMNS}, C_eq=10.0, D_p=0.8, beta=0.7, k_T=0.8, k_E=0.8)
    nom = nominal_params(overrides={'controller:control.leakage_compensation': 0.5})
    plant = plant_params(nom['plant_sim'], mult)
    Ts = plant['plant.sim.Ts']
    ref, load, faults, commands = SC.signals(scn, Ts)
    n = len(ref)
    mean_error = {}
    for stop in (True, False):
        loop = build_loop({**nom, 'plant_sim': plant}, campaign.noise_seed(1, 0),
                          schedule(faults, n, Ts), schedule(commands, n, Ts))
        assert loop.ctl.compensating
        if not stop:
            loop.ctl.stop_leakage_compensation = lambda: False
        rec = loop.run(ref, load)
        after = np.arange(n) * Ts > 2.5
        mean_error[stop] = abs(np.mean(rec[after, CL.R_X0] - ref[after]))
        assert loop.ctl.compensating is not stop
        assert loop.mgr.pressure_sensor_fault and loop.mgr.name == 'ACTIVE_B'
        assert not loop.est.use_pressure       # the estimator stopped reading them, too
    print(f'mean tracking error after 2.5 s: {mean_error[True] * 1e6:.1f} um stopped, '
          f'{mean_error[False] * 1e6:.1f} um kept on')
    assert mean_error[True] < 50e-6 and mean_error[False] > 200e-6


# --------------------------------------------------------------------------- compiled path
def test_manager_tick_equals_the_python_state_machine(params):
    """The node's per-state path (core.redundancy.stepper.ManagerTick: compiled while nothing
    happens) against SwitchManager.update on the same states: 24 runs of 3 s whose segments
    trip and clear every monitor, faults on either drive, commanded switches, the safe state,
    the loop open, commands lost, late and spread (the band of references the node's deque
    gave), a drive spinning up after its enable (a commanded switch waits for the speeds to
    match), the pressure sensors blamed (a pressure residual on both drivers). The same select,
    state, events and health arrays on every tick."""
    from eha_ros.core.redundancy import stepper as RS
    rng = np.random.default_rng(7)
    k_T, D_p = params['plant.motor.k_T'], params['plant.pump.D_p']
    compiled = ticks = 0
    kinds, reasons = collections.Counter(), []
    for run in range(24):
        py, fast = SwitchManager(params), SwitchManager(params)
        tick = RS.ManagerTick(fast, max_age=50)
        refs = collections.deque(maxlen=256)
        k, ref = 0, 100.0
        on = [-100, -100]           # tick each drive was last enabled: it spins up in 15 ticks
        while k < 3000:
            n = int(rng.integers(20, 600))
            sick = rng.choice(['none', 'none', 'speed', 'current', 'pressure', 'estimator',
                               'fault', 'fault', 'nan_pressure'])
            faulty = int(rng.integers(0, 2))
            loop_ok = bool(rng.random() > 0.1)
            spread = 0.0 if rng.random() < 0.5 else 10.0       # the commands' references
            if rng.random() < 0.15:
                c = int(rng.integers(0, 2))
                assert py.request(c, 'test') == tick.request(c, 'test')
            if rng.random() < 0.02:
                assert py.safe_state('test') == tick.safe_state('test')
            for _ in range(n):
                sel = py.select
                w, i, inn, pd = 100.0, 1.0 + 0.1 * rng.standard_normal(), 1e-5, None
                flt = [False, False]
                if sick == 'speed':
                    w = -200.0
                elif sick == 'current':
                    i = 35.0
                elif sick == 'pressure':
                    i, pd = 10.0, 20e5
                elif sick == 'estimator':
                    inn = 2e-3
                elif sick == 'fault':
                    flt[faulty] = True
                pd = k_T * i / D_p if pd is None else pd
                on = [on[c] if sel.drive_enable[c] else k + 1 for c in range(2)]
                speed = np.array([w * min(1.0, (k - on[c] + 1) / 15.0) if e else 0.0
                                  for c, e in enumerate(sel.drive_enable)])
                current = np.array([i if e else 0.0 for e in sel.drive_enable])
                pa = math.nan if sick == 'nan_pressure' else 1e6 + pd
                if rng.random() < 0.9:          # a command, sometimes lost or late
                    ref = 100.0 + spread * rng.standard_normal()
                    cmd = k - int(rng.integers(0, 3))
                    refs.append((cmd, ref))
                    tick.command(cmd, ref)
                # the node's band before ManagerTick kept it: the deque, the last 108, 50 ticks
                recent = [r for c, r in list(refs)[::-1][:108] if c >= k - 50]
                band = (min(recent), max(recent)) if recent else None
                py.update(ChannelSample(k * 1e-3, ref, tuple(speed), tuple(current), pa, 1e6,
                                        sel.drive_enable, tuple(flt), True, inn, True, loop_ok,
                                        band), k)
                packed = tick.a
                tick.update(k * 1e-3, k, ref, loop_ok, speed, current, pa, 1e6,
                            sel.drive_enable, flt, inn, True)
                compiled += tick.a is packed           # re-packed only after the Python path
                assert (fast.select, fast.name, fast.t, fast.seq) == \
                    (py.select, py.name, py.t, py.seq), (run, k)
                assert np.array_equal(fast.health.ms, py.health.ms, equal_nan=True), (run, k)
                assert np.array_equal(fast.health.hs, py.health.hs, equal_nan=True), (run, k)
                k += 1
        ticks += k
        assert [(e.kind, e.t, e.reason) for e in fast.events] == \
            [(e.kind, e.t, e.reason) for e in py.events]
        kinds.update(e.kind for e in py.events)
        reasons += [e.reason for e in py.events]
    opened = collections.Counter(re.search(r'valves opened after (\d+) ms', r).group(1)
                                 for r in reasons if 'valves opened' in r)
    print(f'events {dict(kinds)}; {compiled} of {ticks} ticks compiled; valves opened after '
          f'(ms: switches) {dict(opened)}')
    assert set(opened) - {'0', '50'}, 'no switch waited for the speeds to match'
    assert {'switch_start', 'switch_done', 'safe', 'degraded', 'restored',
            'sensor_fault'} <= set(kinds)         # sensor_fault: 'pressure' on either driver
    assert 0.9 * ticks < compiled < ticks - 50       # both paths taken
