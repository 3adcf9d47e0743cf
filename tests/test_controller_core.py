"""Position controller core: Tustin keeps the continuous margins, the observer-form anti-windup
tames saturating steps and a held piston, reference handling, bumpless restart."""
import math

import numpy as np
import pytest
import yaml
from scipy import signal

from eha_ros.core.controller.discrete import freqresp_z, tustin
from eha_ros.core.controller.position import PositionController, drive_reach_of, tf_to_ss
from eha_ros.core.plant import EhaPlant, linear
from eha_ros.core.plant.parameters import nominal_plant
from eha_ros.core.qft.report import read_antiwindup_poles

TS = 1e-3
P = nominal_plant()


def controller_tfs(path='config/controller.yaml'):
    d = yaml.safe_load(open(path))['controller']['ros__parameters']
    return ((d['position_controller']['num'], d['position_controller']['den']),
            (d['prefilter']['num'], d['prefilter']['den']))


def aw_poles(path='config/controller.yaml'):
    return read_antiwindup_poles(path)


def make(path='config/controller.yaml', aw=True, rate=0.19, accel=0.0, drive_limit=True):
    G, F = controller_tfs(path)
    return PositionController(G, F, TS, P['plant.drive.omega_max'], P['plant.cylinder.stroke'],
                              0.005, rate, antiwindup=aw, aw_poles=aw_poles(path),
                              accel_limit=accel,
                              drive_reach=drive_reach_of(P) if drive_limit else 0.0)


def margins(w, L):
    """Gain margin (dB) and phase margin (deg) from a dense open-loop response."""
    mag, ph = np.abs(L), np.unwrap(np.angle(L))
    i = np.nonzero(np.diff(np.sign(mag - 1.0)))[0]
    pm = 180 + np.degrees(np.interp(1.0, mag[i[0] + 1:i[0] - 1:-1], ph[i[0] + 1:i[0] - 1:-1])) \
        if i.size else np.inf
    j = np.nonzero(np.diff(np.sign(ph + np.pi)))[0]
    gm = -20 * np.log10(mag[j[0]]) if j.size else np.inf
    return gm, pm


@pytest.mark.parametrize('path', ['config/controller.yaml', 'config/controller_thesis.yaml'])
def test_discrete_loop_keeps_continuous_margins(path):
    """Continuous G P e^{-s T_d} vs the digital loop actually run: Tustin(G), ZOH plant, delays.

    T_d = Ts (command applied at the next tick) + drive delay + Ts/2 (hold)."""
    G, _ = controller_tfs(path)
    abcd = linear.velocity_abcd(P, lowpass=True)
    delay_ticks = 1 + int(round(P['plant.drive.delay'] / TS))
    w = np.logspace(0, math.log10(0.9 * math.pi / TS), 3000)
    Gc = signal.freqresp(signal.lti(*G), w)[1]
    Lc = Gc * linear.freqresp(abcd, w) * np.exp(-1j * w * (delay_ticks * TS + TS / 2))
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete(abcd[:2] + (abcd[2][:1], abcd[3][:1, :1]), TS, 'zoh')
    Pd = freqresp_z(Ad, Bd[:, :1], Cd, Dd[:, :1], w, TS)
    Gd = freqresp_z(*tustin(*tf_to_ss(*G), TS), w, TS)
    Ld = Gd * Pd * np.exp(-1j * w * delay_ticks * TS)
    gm_c, pm_c = margins(w, Lc)
    gm_d, pm_d = margins(w, Ld)
    print(f'{path}: continuous GM {gm_c:.2f} dB PM {pm_c:.1f} deg; digital GM {gm_d:.2f} dB '
          f'PM {pm_d:.1f} deg')
    assert abs(gm_c - gm_d) < 1.0 and abs(pm_c - pm_d) < 5.0
    assert pm_d > 0 and gm_d > 0


@pytest.fixture(scope='module')
def saturation():
    """qft.antiwindup.saturation_figures of the stack's controller (nonlinear nominal plant):
    40 mm step with the reference limits lifted, piston held 1 s at a 2 mm error then released,
    2 mm jump of the reference; as the stack runs it ('stack': the anti-windup's actuator
    bounded by the clamp and the drive's reach beyond the motor speed), with the clamp only
    ('clamp') and without anti-windup ('off')."""
    from eha_ros.core.qft.antiwindup import saturation_figures
    G, F = controller_tfs()
    return {'stack': saturation_figures(G, F, aw_poles(), P),
            'clamp': saturation_figures(G, F, aw_poles(), P, drive_limit=False),
            'off': saturation_figures(G, F, None, P)}


def test_antiwindup_saturating_40mm_step(saturation):
    """40 mm step, rate limit 5 m/s, no acceleration limit: the 838 rad/s clamp holds ~0.2 s."""
    on, off = saturation['stack'], saturation['off']
    print(f"40 mm step overshoot: {off['step_40mm_overshoot_pct']:.1f} % without anti-windup, "
          f"{on['step_40mm_overshoot_pct']:.2f} % with, 2 % settling {on['step_40mm_settling_s']:.3f} s")
    assert off['step_40mm_overshoot_pct'] > 10.0          # the windup this is about
    assert on['step_40mm_overshoot_pct'] <= 5.0 and on['step_40mm_settling_s'] <= 0.3


def test_antiwindup_held_piston(saturation):
    """Piston held 1 s with a 2 mm error: the output stays at the clamp of the error's sign and
    the unclamped output stays bounded; after the release, and after a plain 2 mm jump from
    rest, the overshoot is within 5 % (issue 17). Both moves are limited by the drive's current
    (the motor starts from standstill): with the clamp as the anti-windup's only actuator limit
    G's state runs ahead of the motor (the jump overshoots > 5 %), without anti-windup it winds
    up (~200 % after the hold)."""
    on, clamp, off = saturation['stack'], saturation['clamp'], saturation['off']
    print(f"held: unclamped output {on['held_u_min']:.0f}..{on['held_u_max']:.0f} rad/s; release "
          f"overshoot {on['held_release_overshoot_pct']:.2f} %, settling "
          f"{on['held_release_settling_s']:.3f} s; 2 mm jump {on['jump_2mm_overshoot_pct']:.2f} % "
          f"(clamp only: {clamp['held_release_overshoot_pct']:.1f} / "
          f"{clamp['jump_2mm_overshoot_pct']:.1f} %; without anti-windup: "
          f"{off['held_release_overshoot_pct']:.0f} %)")
    assert on['held_clamped_same_sign'] and on['held_u_min'] > 838.0
    assert on['held_u_max'] < 3.0 * off['held_u_max'] / 2
    assert off['held_release_overshoot_pct'] > 100.0
    assert clamp['jump_2mm_overshoot_pct'] > 5.0          # what the drive's reach is for
    assert on['held_release_overshoot_pct'] <= 5.0 and on['held_release_settling_s'] <= 0.1
    assert on['jump_2mm_overshoot_pct'] <= 5.0 and on['jump_2mm_settling_s'] <= 0.1


def test_drive_reach_is_what_the_drive_can_follow():
    """antiwindup.drive_reach from plant.yaml: the speed error that puts the drive at its
    current limit plus the current-limited acceleration over Ts and the drive's delay. On the
    nonlinear plant a motor at rest given 838 rad/s gains k_T I_max/J_eq per second (within
    15 %: the pump's load and viscous damping), and a reference within the reach of the motor
    speed changes nothing in the controller (exactly Tustin(G)), one beyond it does."""
    reach = drive_reach_of(P)
    torque = P['plant.motor.k_T'] * P['plant.drive.I_max']
    accel = torque / P['plant.motor.J_eq']
    assert reach == pytest.approx(torque / P['plant.drive.Kp_w'] + accel * 2e-3)
    plant = EhaPlant(P, seed=1)
    w = []
    for _ in range(12):
        plant.step(P['plant.drive.omega_max'], 0.0)
        w.append(plant.truth().motor_speed[0])
    gain = np.diff(w[4:10]).mean() / TS                  # after the drive's delay
    print(f'drive reach {reach:.1f} rad/s; motor from rest: {gain:.0f} rad/s^2 '
          f'(k_T I_max/J_eq {accel:.0f})')
    assert 0.85 * accel < gain <= accel
    outs = {}
    for name in ('none', 'following', 'at rest'):
        ctl = make()
        ctl.start(0.0)
        ctl.request(2e-4)
        u, last = [], 0.0
        for _ in range(60):
            o = ctl.update(0.0, {'none': math.nan, 'following': last, 'at rest': 0.0}[name])
            last = o.speed_ref                           # a motor one tick behind
            u.append(o.unsaturated)
        outs[name] = (np.array(u), ctl.c.get('drive_limited_ticks', 0))
    assert outs['following'][1] == 0 and np.array_equal(outs['following'][0], outs['none'][0])
    assert outs['at rest'][1] > 0 and not np.array_equal(outs['at rest'][0], outs['none'][0])


def test_190mm_per_s_ramp_tracked_with_the_clamp_active():
    """A 40 mm ramp at 190 mm/s (Table 3.1's maximum velocity) reaches the reference shaper
    unchanged and the loop follows it within its lag; the anti-windup changes nothing while the
    output is below the clamp."""
    res = {}
    for aw in (True, False):
        ctl = make(aw=aw)
        plant = EhaPlant(P, seed=1)
        ctl.start(0.0)
        xs, refs = np.empty(700), np.empty(700)
        for k in range(700):
            refs[k] = min(0.04, 0.19 * TS * (k + 1))
            ctl.request(refs[k])
            o = ctl.update(plant.truth().position, plant.measure().motor_speed[0])
            plant.step(o.speed_ref, 0.0)
            xs[k] = plant.truth().position
        res[aw] = (xs, ctl.c.get('saturated_ticks', 0))
    xs, sat = res[True]
    lag = refs[100:200] - xs[100:200]
    print(f'190 mm/s ramp: lag {1e3 * lag.mean():.3f} +- {1e3 * np.ptp(lag):.3f} mm (the '
          f'prefilter\'s), clamp active {sat} ticks (without anti-windup {res[False][1]}), '
          f'overshoot {1e6 * (xs.max() - 0.04):.1f} um, max |x_aw - x_no_aw| '
          f'{1e6 * np.abs(xs - res[False][0]).max():.1f} um')
    assert np.ptp(lag) < 0.1e-3 and lag.mean() < 3e-3       # a steady lag: the ramp is followed
    assert xs.max() - 0.04 <= 0.05 * 0.04 and abs(xs[-1] - 0.04) < 50e-6


def test_reference_nan_rejected_clamped_and_rate_limited():
    ctl = make()
    ctl.start(0.0)
    assert not ctl.request(float('nan'))
    assert ctl.request(0.2)                       # beyond the stroke: clamped to 55 mm
    assert ctl.c['rejected_references'] == 1 and ctl.c['clamped_references'] == 1
    refs = [ctl.ref.next() for _ in range(400)]
    assert np.max(np.diff(refs)) <= 0.19 * TS + 1e-12
    assert refs[-1] == pytest.approx(0.055)


def test_bumpless_restart_and_hold():
    ctl = make()
    ctl.start(0.01)                               # piston at 10 mm, no reference yet
    out = ctl.update(0.01)
    assert abs(out.speed_ref) < 1e-9 and out.reference == pytest.approx(0.01)
    for _ in range(50):
        ctl.update(0.0101)
    ctl.hold_integrator(20)
    x = ctl.G.x.copy()
    for _ in range(20):
        ctl.update(0.0102)
    assert np.array_equal(ctl.G.x, x)             # G's state frozen during the hold


def test_jumped_reference_moves_with_bounded_acceleration_and_sines_pass_unchanged():
    from eha_ros.core.controller.reference import ReferenceShaper
    from eha_ros.core.stats import Counters
    sh = ReferenceShaper(0.12, 0.005, 0.19, TS, Counters(), accel_limit=10.0)
    sh.start_from(0.0)
    sh.request(0.005)
    r = np.array([0.0] + [sh.next() for _ in range(200)])
    v = np.diff(r) / TS
    a = np.diff(v) / TS
    assert r.max() == 0.005 and r[-1] == 0.005 and np.all(np.diff(r) >= 0)   # no overshoot
    assert np.max(v) <= 0.19 + 1e-12
    assert np.max(np.abs(a)) <= 1.2 * 10.0           # the arrival snap: a little over a
    assert np.nonzero(r == 0.005)[0][0] < 0.05 / TS  # there in 2 sqrt(d/a) ~ 45 ms
    for f in (1.0, 7.0, 15.0):                       # feasible targets are followed exactly
        sh = ReferenceShaper(0.12, 0.005, 0.19, TS, Counters(), accel_limit=10.0)
        sh.start_from(0.0)
        for k in range(1000):
            target = 1e-3 * math.sin(2 * math.pi * f * k * TS)
            sh.request(target)
            assert sh.next() == target


def test_5mm_step_on_the_nonlinear_plant_overshoot_settling():
    """Issue 6 step figures on the nonlinear plant (estimator in the loop, batch). Without the
    acceleration limit the 190 mm/s ramp alone drives the speed clamp; the observer-form
    anti-windup keeps that step within the spec too (0.14 %; conditional integration of the
    earlier controller: about 11 %)."""
    from eha_ros.core.sim.batch import BatchStack
    res = {}
    for acc in (10.0, 0.0):
        st = BatchStack(overrides={'controller': {'controller:control.accel_limit': acc}})
        for _ in range(500):
            st.tick(0.0)
        x = np.array([st.tick(0.005).truth for _ in range(1500)])
        out = np.nonzero(np.abs(x - 0.005) > 0.02 * 0.005)[0]
        res[acc] = (100 * (x.max() - 0.005) / 0.005, (out[-1] + 1) * TS,
                    abs(x[-300:].mean() - 0.005))
    print(f'5 mm step (overshoot %, 2 % settling s, steady error m): with 10 m/s^2 {res[10.0]}, '
          f'rate limit only {res[0.0]}')
    overshoot, settling, steady = res[10.0]
    assert overshoot <= 5.0 and settling <= 0.3 and steady <= 20e-6
    assert res[0.0][0] <= 5.0 and res[0.0][1] <= 0.3


def test_reference_acceleration_within_the_weakest_drive_of_the_family():
    """control.accel_limit comes from the family: the drive's current limit bounds the piston
    acceleration at k_T I_max D_p / (J_eq A_p); on the weakest plant of Table 4.5 (k_T and D_p
    x0.8) that is 7.4 m/s^2. Beyond it the drive saturates below the speed clamp the
    anti-windup knows; with the observer-form anti-windup the step stays within the spec even
    then (10 m/s^2: 0.14 %; with the conditional integration of the earlier controller: 12.6 %)."""
    import os
    from eha_ros.core.qft.spec import load_spec
    from eha_ros.core.sim import campaign, scenarios
    nom = campaign.nominal_params()
    spec = load_spec(os.path.join('config', 'qft_spec.yaml'))
    kT, Dp = spec['family.k_T_range'][0], spec['family.D_p_range'][0]
    pl = nom['plant_sim']
    a_max = (kT * pl['plant.motor.k_T'] * pl['plant.drive.I_max'] * Dp * pl['plant.pump.D_p']
             / (pl['plant.motor.J_eq'] * pl['plant.cylinder.A_p']))
    acc = nom['controller']['control.accel_limit']
    weakest = dict(C_eq=1.0, D_p=Dp, beta=1.0, k_T=kT, k_E=spec['family.k_E_range'][1])
    figs = {}
    for a in (acc, 10.0):
        n = dict(nom, controller=dict(nom['controller'], **{'control.accel_limit': a}))
        figs[a], _ = scenarios.run(scenarios.load('step'), n, weakest, seed=1, trace=False)
    print(f'\nweakest drive: {a_max:.2f} m/s^2; 5 mm step overshoot with {acc:g} m/s^2 '
          f'{figs[acc]["overshoot_pct"]:.2f} %, with 10 m/s^2 {figs[10.0]["overshoot_pct"]:.2f} %')
    assert acc <= 0.85 * a_max
    assert figs[acc]['overshoot_pct'] <= 5.0 and figs[acc]['settling_s'] <= 0.3
    assert figs[10.0]['overshoot_pct'] <= 5.0


def test_drive_mismatch_of_the_velocity_loop():
    """The controller node warns when its G_v (velocity_controller) is not the drive of
    plant.yaml (eq. 4.71): the shipped pair matches, a changed gain is measured, another order
    is inf."""
    from eha_ros.core.controller.params import SCHEMA
    from eha_ros.core.controller.velocity_loop import drive_mismatch
    from eha_ros.core.sim.batch import node_params
    p = node_params('controller', SCHEMA)
    print(f'shipped: {drive_mismatch(p):.2e}')
    assert drive_mismatch(p) <= p['control.drive_check_tolerance']
    q = dict(p, **{'plant.drive.Kp_w': 1.2 * p['plant.drive.Kp_w']})
    # the YAML's G_v against a drive with 20 % more Kp_w: |1 - 1.2| / 1.2 = 1/6
    assert drive_mismatch(q) == pytest.approx(1 / 6, rel=1e-9)
    r = dict(p, **{'velocity_controller.den': [1.0, 5.0]})
    assert drive_mismatch(r) == float('inf')


def test_tick_sync_pairs_references_with_their_estimates():
    """The controller node's lock-step pairing (core.controller.tick_sync): a tick-locked
    reference k waits for estimate k; in lock-step an estimate beyond the newest reference
    waits for it, at most ``wait`` (here 50 ms; counted); an untimed reference (seq 0, the
    sweep's last) ends the tick-locked source."""
    from types import SimpleNamespace as E
    from eha_ros.core.controller.tick_sync import TickSync
    s = TickSync(lockstep=True, wait=0.05)
    assert s.reference(0, 1e-3, last_seq=10)            # untimed: at once
    assert not s.reference(12, 2e-3, last_seq=10)       # tick 12: queued
    assert not s.reference(13, 3e-3, last_seq=10)
    assert s.reference(9, 4e-3, last_seq=10)            # its tick is past: at once
    assert s.due(11) == [] and s.due(12) == [2e-3] and s.due(20) == [3e-3]
    assert not s.hold(E(seq=13), now=0.0)               # its reference (13) came
    assert s.hold(E(seq=14), now=0.0) and s.hold(E(seq=15), now=0.01)
    assert s.pop_ready(0.02) is None                    # waiting, within 50 ms
    assert not s.reference(14, 5e-3, last_seq=13)
    assert s.pop_ready(0.02).seq == 14 and s.pop_ready(0.02) is None
    assert s.pop_ready(0.07).seq == 15                  # waited 60 ms: released, counted
    assert s.c.get('reference_wait_timeouts', 0) == 1
    assert s.hold(E(seq=16), now=1.0) and s.pop_ready(1.0, force=True).seq == 16
    assert s.c.get('reference_wait_timeouts', 0) == 1   # forced: not a timeout
    # the sweep ends: its seq 0 drops the references still queued and releases held estimates
    assert not s.reference(30, 6e-3, last_seq=16) and s.hold(E(seq=31), now=2.0)
    assert s.pop_ready(2.0) is None
    assert s.reference(0, 0.0, last_seq=16)
    assert s.due(40) == [] and s.pop_ready(2.0).seq == 31
    assert not s.hold(E(seq=32), now=2.0)               # no source: nothing waits
    assert s.c.get('reference_wait_timeouts', 0) == 1
    real_time = TickSync(lockstep=False, wait=0.05)
    assert not real_time.hold(E(seq=99), now=0.0)       # only lock-step waits


def test_the_leakage_compensation_stiffens_the_softest_corner_and_keeps_the_piston_still():
    """Issue 42: control.leakage_compensation = 1 supplies the leak flow the estimator reports
    (adapt.leak_flow) as pump speed. Campaign scenario stiffness (5 kN at 1, 4, 7 Hz) on the
    softest corner of Table 4.5 (C_eq x10, D_p x0.8, beta x0.7, k_T x0.8, k_E x0.8, whose
    loaded leakage is x14.7), nonlinear plant, estimator in the loop: 45.6 / 40.6 / 34.7 kN/mm
    without, above eq. 4.60's 49 with. A fixed compensation of 8 x C_eq (measured, not kept)
    made the nominal plant hunt at 36 Hz after a step (30 um peak to peak, where the loop
    without it rests within 8 um): over-compensated, a plant leaks negatively, and against
    Stribeck friction that is an oscillator. The estimator's leak flow does not
    over-compensate: the nominal plant rests as still as without it."""
    from eha_ros.core.sim import campaign, scenarios
    nominal = campaign.nominal_params()
    stiffness, step = scenarios.load('stiffness'), scenarios.load('step')
    keys = [f'stiffness_kn_per_mm_{f}hz' for f in (1, 4, 7)]
    corner = dict(C_eq=10.0, D_p=0.8, beta=0.7, k_T=0.8, k_E=0.8)
    run151 = dict(C_eq=1.0, D_p=1.0, beta=0.98 ** 0.5, k_T=1.2, k_E=0.96 ** 0.5)  # Table 4.5
    out = {}
    for alpha in (0.0, 1.0):
        nominal['controller'] = dict(nominal['controller'],
                                     **{'control.leakage_compensation': alpha})
        f = scenarios.run(stiffness, nominal, corner, 1, trace=False)[0]
        out['corner', alpha] = [f[k] for k in keys]
        f = scenarios.run(step, nominal, run151, campaign.noise_seed(1, 151), trace=False)[0]
        out['ripple', alpha] = f['steady_ripple_m'] * 1e6
    print({k: np.round(v, 1).tolist() for k, v in out.items()})
    assert min(out['corner', 0.0]) < 49.0
    assert min(out['corner', 1.0]) > 1.1 * 49.0
    assert out['ripple', 1.0] < 1.3 * out['ripple', 0.0] + 2.0
