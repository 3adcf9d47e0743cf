"""Issue 15: the estimator on the plant family of Table 4.5 (core only, no DDS).

The adaptive chamber EKF (core.estimator.adapt: leakage, displacement, compliance corrections
with the leakage Jacobian, estimate projection, gated adaptation, load-step process noise),
the consistency monitor (sensor fault vs model mismatch vs filter/sensor disagreement) and the
tuning derived from the family (core.estimator.tuning, scripts/tune_estimator). Closed loop:
nonlinear plant varied through plant_sim overrides, estimator and controller nominal
(core.sim.batch.BatchStack, compiled path)."""
import math
import os

import numpy as np
import pytest
from scipy.linalg import expm

from eha_ros.core.sim.batch import BatchStack, node_params
from eha_ros.core.sim.closed_loop import (R_FAULT, R_NISDIM, R_SKIP, R_U, R_X, R_XHAT,
                                          R_XM)
from eha_ros.core.estimator import adapt, tuning
from eha_ros.core.estimator import fault_detector as fd
from eha_ros.core.estimator.params import DEFAULT_STAGES, without
from eha_ros.core.estimator.chamber_kf import ChamberKF, continuous, leak_sensitivity
from eha_ros.core.estimator.estimator import Estimator
from eha_ros.core.hardware.sim_params import SCHEMA as SIM
from eha_ros.core.qft.family import scaled_params

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
KEYS = ('plant.pump.C_p', 'plant.cylinder.C_c', 'plant.pump.C_r', 'plant.pump.D_p',
        'plant.fluid.beta', 'plant.motor.k_T', 'plant.motor.k_E')


def plant(scale, noise=True):
    """plant_sim overrides of a Table 4.5 plant [C_eq, D_p, beta, k_T, k_E]."""
    p = scaled_params(node_params('plant_sim', SIM), scale)
    return dict({k: p[k] for k in KEYS}, **({} if noise else {'plant.sensors.noise': False}))


def stack(scale, seed=1, faults=None, est=None, noise=True):
    return BatchStack(seed=seed, overrides={'plant_sim': plant(scale, noise),
                                            'estimator': est or {}}, faults=faults)


def run(s, refs, loads=None):
    return s._loop.run(np.asarray(refs, float), None if loads is None else np.asarray(loads, float))


# ------------------------------------------------------------------ the adaptive EKF
def test_leak_sensitivity_is_the_derivative_of_the_zoh(params):
    kf = Estimator(params).kf
    c, Ts = kf.c, kf.Ts
    A, _ = continuous(c, True, False, 1.0)
    D = leak_sensitivity(c, A, Ts, kf.n)[:A.shape[0], :A.shape[0]]
    AL = np.zeros_like(A)
    k = c.beta / c.V_d
    for i in (2, 3):
        AL[i, i], AL[i, 5 - i] = -k * (c.C_x + c.C_r), k * c.C_x
    h = 1e-4
    fd_ = (expm((A + h * AL) * Ts) - expm((A - h * AL) * Ts)) / (2 * h)
    assert np.allclose(D, fd_, rtol=1e-5, atol=1e-9 * np.abs(fd_).max())


def test_adaptive_predict_is_the_ekf_with_the_leakage_jacobian(params):
    """Mean: F (with the parameter columns) x + G u; covariance: Fj P Fj' + Q with
    Fj = F + lambda D (the Jacobian of the leakage flow lambda C p in p)."""
    kf = Estimator(params).kf
    assert isinstance(kf, ChamberKF) and min(kf.i_leakage, kf.i_displacement, kf.i_compliance) > 0
    rng = np.random.default_rng(1)
    kf.x[2:4] = kf.c.p_acc + np.array([20e5, -0.3e5])
    kf.x[kf.i_leakage], kf.x[kf.i_displacement], kf.x[kf.i_compliance] = 4.0, -0.1, 0.2
    A = rng.normal(size=(kf.n, kf.n)) * np.sqrt(np.diag(kf.P))
    kf.P = A @ A.T / kf.n + np.diag(np.diag(kf.P))
    x0, P0 = kf.x.copy(), kf.P.copy()
    kf.predict(300.0, 19e5)
    F, G = kf.F, kf.G                  # the check-valve state's pair with its parameter columns
    Fj = F.copy()
    nl = kf._n_lin
    Fj[:nl, :nl] += 4.0 * kf.Dm[kf.mode * kf.n:kf.mode * kf.n + nl, :nl]
    assert np.allclose(kf.x, F @ x0 + G @ kf.u, rtol=1e-12, atol=1e-12)
    assert np.allclose(kf.P, Fj @ P0 @ Fj.T + kf.Q, rtol=1e-10, atol=1e-14)
    # the leakage column is the flow lambda C (p - ...) through the ZOH of a unit flow
    assert np.any(F[:nl, kf.i_leakage] != 0.0) and np.any(F[:nl, kf.i_displacement] != 0.0)


def test_projection_bounds_and_offset_band(params):
    kf = Estimator(params).kf
    i_lam, i_del = kf.i_leakage, kf.i_displacement
    kf.x[i_lam], kf.x[i_del], kf.x[kf.i_compliance], kf.x[kf.i_gm] = 99.0, -9.0, 0.1, -1e-3
    assert kf.project() == 0          # a clip: the projection at work, no verdict yet
    assert kf.x[i_lam] == kf.leakage_range[1] and kf.x[i_del] == kf.displacement_range[0]
    assert kf.x[kf.i_compliance] == 0.1 and kf.x[kf.i_gm] == -kf.offset_bound
    for _ in range(adapt.EDGE_TICKS - 2):
        kf.x[kf.i_leakage] = 99.0
        assert kf.project() == 0
    kf.x[kf.i_leakage] = 99.0
    assert kf.project() == 1          # held on its bound: the model is at its edge


def _predict_mode(est, p_a, p_b, omega, measured=(np.nan, np.nan)):
    """The check-valve state the chamber filter's next prediction takes from these priors and
    the ``measured`` chamber pressures (NaN: none)."""
    kf = est.kf
    kf.x[:] = 0.0
    kf.x[1] = kf.c.D_p * omega / kf.c.A_p          # the piston moving with the pump's flow
    kf.x[2], kf.x[3] = p_a, p_b
    kf.p_last[:2] = p_a, p_b
    est.omega_prev = omega
    est._predict_tick(*est.kernel, omega, *measured)
    return int(est.E['mode'][0])


def test_a_check_valve_passes_no_reverse_flow(params):
    """stepper.valve_state: a chamber below p_c takes its valve open (an inflow from the
    accumulator) unless the tick's flows lift it above p_c with the valve shut and its measured
    pressure does not put it clearly below p_c. The open mode's linear conductance would
    otherwise hand the pump's flow back: at every reversal of a 1 Hz sine on a stiff oil (beta
    x1.4, friction x1.9) the filling chamber lost 30 um of piston travel, and the estimate kept
    the step for half a cycle."""
    est = Estimator(params)
    p_c = est.kf.c.p_c
    low, near = p_c - 2e5, p_c - 1e3
    assert _predict_mode(est, low, low, 0.0) == 3         # both filled from their valves
    pump = 20.0                                  # rad/s into A: 5 mm/s of piston speed
    assert _predict_mode(est, near, near, pump) == 1      # A pressurizes: shut; B drains
    assert _predict_mode(est, near, near, -pump) == 2     # and the other way round
    # a measured pressure clearly below p_c (VALVE_GATE sigma of the sensor noise) says the
    # chamber sits on its valve, whatever the states predict; one within the gate does not
    sigma = np.sqrt(est.kf.R[1, 1])
    assert _predict_mode(est, near, near, pump, (p_c - 3 * sigma, p_c - 3 * sigma)) == 3
    assert _predict_mode(est, near, near, pump, (p_c - 1 * sigma, p_c - 3 * sigma)) == 1
    assert _predict_mode(est, near, near, pump) == 1      # no sample: the prediction decides


def test_stiff_oil_sine_without_a_step_at_the_reversals():
    """The estimator given the plant's true parameters (no adaptive states) on a stiff-oil,
    high-friction, tight plant of the random box (its run 164, tuning seed 1): the 1 Hz 5 mm
    sine's estimate error has no step at the reversals (before the valve fix: a 29 um step
    kept for half of every cycle, RMSE ratio 1.05; now 0.14)."""
    from eha_ros.core.sim import scenarios as SC
    from eha_ros.core.sim.batch import nominal_params
    from eha_ros.core.sim.family import plant_params
    mult = dict(C_eq=0.424, D_p=0.863, beta=1.406, k_T=0.796, k_E=0.978, friction=1.881,
                noise=1.182, leak_split=1.633)
    nom = nominal_params()
    est = plant_params(nom['estimator'], mult)
    est['estimator.stages'] = [s for s in est['estimator.stages'] if not s.startswith('adapt_')]
    scn = SC.load('sine')
    Ts = nom['plant_sim']['plant.sim.Ts']
    ref, load, _, _ = SC.signals(scn, Ts)
    from eha_ros.core.sim.batch import build_loop
    from eha_ros.core.sim.closed_loop import R_X0, R_XHAT, R_XM
    loop = build_loop({**nom, 'estimator': est, 'plant_sim': plant_params(nom['plant_sim'], mult)},
                      1681193079977255259)
    rec = loop.run(ref, load)
    t = np.arange(len(ref)) * Ts
    w = t >= 6.0
    e = rec[w, R_XHAT] - rec[w, R_X0]
    ratio = np.sqrt(np.mean(e ** 2)) / np.sqrt(np.mean((rec[w, R_XM] - rec[w, R_X0]) ** 2))
    rising = np.cos(2 * np.pi * t[w]) > 0            # the reference's velocity sign
    step = abs(e[rising].mean() - e[~rising].mean())
    print(f'stiff oil: RMSE ratio {ratio:.3f}, error rising - falling {step * 1e6:.1f} um')
    assert ratio < 0.3 and step < 8e-6


def test_a_load_step_on_the_softest_corner_is_no_sensor_jump():
    """Table 4.5 plant 219 (C_eq x10, D_p x0.8, beta x0.7, k_E x0.8), campaign scenario switch
    with held-out seed 104's noise: the 10 kN load step at 1 s. With the valve state from the
    filter's prediction alone a valve was taken shut while its chamber's measured pressure sat
    more than VALVE_GATE sigma below p_c: a 6.6 mm estimate error, a position jump reported and
    the safe state. The measured pressure keeps that valve open (stepper.valve_state)."""
    from eha_ros.core.sim import closed_loop as CL
    from eha_ros.core.sim import scenarios as SC
    from eha_ros.core.sim.batch import build_loop, nominal_params
    from eha_ros.core.sim.family import plant_params
    from eha_ros.core.sim.switchover import schedule
    mult = dict(C_eq=10.0, D_p=0.8, beta=0.7, k_T=0.96 ** 0.5, k_E=0.8, friction=1.0,
                noise=1.0, leak_split=1.0)
    nom = nominal_params()
    plant = plant_params(nom['plant_sim'], mult)
    Ts = plant['plant.sim.Ts']
    ref, load, faults, commands = SC.signals(SC.load('switch'), Ts)
    n = len(ref)
    loop = build_loop({**nom, 'plant_sim': plant}, 5501366623709528335,
                      schedule(faults, n, Ts), schedule(commands, n, Ts))
    rec = loop.run(ref, load)
    err = np.abs(rec[:, CL.R_XHAT] - rec[:, CL.R_X0])
    print(f'plant 219, switch, seed 104: largest estimate error {err.max() * 1e6:.0f} um')
    assert not rec[:, CL.R_FAULT].any() and not rec[:, CL.R_VERDICT].any()
    assert err.max() < 1e-3                        # the load step's transient: 0.67 mm


def _jump_codes(innovations, pds, pz=None, sigma=None, pbs=None):
    """The detector's codes for a sequence of position innovations (m; innovation sigma 30 um
    unless given per sample) and measured p_D (Pa, NaN: the sample's pressures rejected: p_A
    = p_D, p_B = 0 unless ``pbs`` gives chamber B's readings, NaN: rejected); the nominal
    plant's oil."""
    det = fd.FaultDetector(1e-3, jump_debounce=3, jump_step=100e-6, jump_pressure_veto=8.0,
                           pd_per_m=2.0 * 1.379e9 * 2.572e-3 / 4.01e-4)
    det.start(0.0)
    n = len(innovations)
    pz = pz if pz is not None else [0.0] * n
    sigma = sigma if sigma is not None else [30e-6] * n
    pbs = pbs if pbs is not None else [0.0 if pd == pd else math.nan for pd in pds]
    return [det.update(1e-3 * k, y, sg ** 2, z, pa, pb)
            for k, (y, pa, pb, z, sg) in enumerate(zip(innovations, pds, pbs, pz, sigma))]


def test_a_jump_needs_a_step_away_from_zero_and_still_pressures():
    """A sensor jump steps the innovation away from zero and leaves the measured p_D alone; the
    piston moves that fast only by compressing the oil, which moves p_D (2 beta A_p / V_d:
    177 bar per mm at nominal). Random:200's 10 kN step on a beta x0.69 plant (motor_fail,
    noise of held-out seed 104): p_B read below 0 bar on the step's first sample (rejected: no
    pressures, no pressure innovation), p_D 38 bar up on the next; the innovation then fell
    back from -377 to -184 um while beyond the threshold again."""
    quiet = [10e-6, -15e-6, 5e-6]
    jump = quiet + [1e-3] * 5
    assert fd.JUMP in _jump_codes(jump, [1e5] * 8)                  # pressures still
    assert fd.JUMP in _jump_codes([-y for y in jump], [1e5] * 8)
    # the same innovations with the oil compressed (a quarter of 177 bar: 44): p_D up by 50
    # bar on the first sample, or on the second after a rejected first (NaN)
    assert fd.JUMP not in _jump_codes(jump, [1e5] * 3 + [51e5] * 5)
    assert fd.JUMP not in _jump_codes(jump, [1e5] * 3 + [math.nan] + [51e5] * 4)
    # a pressure step too small for the oil to have moved the piston by 1 mm: still a jump
    assert fd.JUMP in _jump_codes(jump, [1e5] * 3 + [5e5] * 5)
    # the pressure innovation's own veto as before
    assert fd.JUMP not in _jump_codes(jump, [math.nan] * 8, pz=[0.0] * 3 + [9.0] + [0.0] * 4)
    # the recorded case (um): the step's run breaks on its second sample (the pressures'
    # information widens S there), a new run starts with the innovation falling back
    fall = [-19e-6, 55e-6, 50e-6, -574e-6, -377e-6, -184e-6, -121e-6, -171e-6, -100e-6]
    sigma = [30e-6] * 4 + [60e-6] + [15e-6] * 4
    pds = [7.8e5, 1.2e5, 0.2e5, math.nan, 37.8e5, 41.7e5, 41.5e5, 46.9e5, 41.6e5]
    assert fd.JUMP not in _jump_codes(fall, pds, sigma=sigma)
    # with the step's direction ignored and no pressures it would have been called a jump
    rise = fall[:5] + [-570e-6, -650e-6, -700e-6, -720e-6]
    assert fd.JUMP in _jump_codes(rise, [math.nan] * 9, sigma=sigma)


def _suspects(innovations, pds, pz=None):
    """fault_detector.suspect after each sample of _jump_codes' detector (innovation sigma
    30 um; pz: the pressures' normalised innovation, 0 unless given). The estimator counts the
    samples it holds back (FaultDetector.suspect_samples); the detector alone holds none."""
    det = fd.FaultDetector(1e-3, jump_debounce=3, jump_step=100e-6, jump_pressure_veto=8.0,
                           pd_per_m=2.0 * 1.379e9 * 2.572e-3 / 4.01e-4)
    det.start(0.0)
    out = []
    pz = pz if pz is not None else [0.0] * len(innovations)
    for k, (y, pd, z) in enumerate(zip(innovations, pds, pz)):
        det.update(1e-3 * k, y, 30e-6 ** 2, z, pd, 0.0)
        out.append(bool(fd.suspect(det.k, det.s)))
    assert det.suspect_samples == 0
    return out


def test_a_run_is_suspect_only_out_of_quiet_innovations_and_until_the_debounce():
    """The samples the estimator holds back (fault_detector.suspect): a run that begins with
    an unvetoed step after QUIET_SAMPLES samples within the threshold, up to the debounce's
    last sample (3 here). A vetoed run is not; nor is a run stepping away again 2 samples
    after a vetoed one (a load step's transient, random:200 plant 194), nor one 2 samples
    after a load step whose position innovation stayed under the threshold while the
    pressures' went far beyond their veto (Table 4.5 plant 122)."""
    quiet = [10e-6, -15e-6] * (fd.QUIET_SAMPLES // 2)
    flags = _suspects(quiet + [1e-3] * 5, [1e5] * (len(quiet) + 5))
    assert flags[-5:] == [True, True, True, False, False] and sum(flags) == 3
    # started too soon: the same jump 10 samples into the run
    flags = _suspects(quiet[:10] + [1e-3] * 5, [1e5] * 15)
    assert not any(flags)
    # the oil compressed on the first sample (p_D 50 bar up): vetoed, not suspect; a new step
    # away 2 samples after it is not suspect either
    pds = [1e5] * len(quiet) + [51e5] * 9
    flags = _suspects(quiet + [-500e-6, -450e-6, -60e-6, -250e-6, -300e-6, -320e-6,
                               -310e-6, -300e-6, -290e-6], pds)
    assert not any(flags)
    # the load step's position innovation just under the threshold (7.7 sigma), its pressures'
    # at 80 sigma; the run 2 samples later: not suspect, and suspect without that pressure
    steps = quiet + [-230e-6, 130e-6, -260e-6, -300e-6, -300e-6]
    pz = [0.0] * len(quiet) + [80.0] + [0.0] * 4
    flags = _suspects(steps, [51e5] * len(steps), pz)
    assert not any(flags)
    flags = _suspects(steps, [51e5] * len(steps))
    assert flags[-3:] == [True, True, True] and sum(flags) == 3


def test_one_valid_pressure_sensor_still_vetoes_a_jump():
    """Chamber B's sensor out of its range (NaN: rejected): a 5 kN load step compresses A's oil,
    A's reading rises (19 bar for 0.22 mm at nominal) and vetoes the jump; a jump leaves it
    still. The threshold is one chamber's half of p_D's: a quarter of 88 bar per mm, 6.6 bar
    for the 0.3 mm here."""
    quiet = [10e-6, -15e-6, 5e-6]
    jump = quiet + [0.3e-3] * 5
    nan = [math.nan] * 8
    assert fd.JUMP in _jump_codes(jump, [10e5] * 8, pbs=nan)
    assert fd.JUMP not in _jump_codes(jump, [10e5] * 3 + [29e5] * 5, pbs=nan)
    # B alone valid, A rejected: the same with B's reading
    assert fd.JUMP not in _jump_codes(jump, nan, pbs=[10e5] * 3 + [29e5] * 5)
    assert fd.JUMP in _jump_codes(jump, nan, pbs=[10e5] * 3 + [15e5] * 5)     # below 6.6 bar
    assert fd.JUMP not in _jump_codes(jump, nan, pbs=[10e5] * 3 + [17e5] * 5)
    # both rejected: no veto by the pressures (as before)
    assert fd.JUMP in _jump_codes(jump, nan, pbs=nan)


def _shaft_codes(*args, **kwargs):
    """:func:`_shaft_detector`'s codes."""
    return _shaft_detector(*args, **kwargs)[1]


def _shaft_detector(innovations, speeds, currents, pa=math.nan, pb=10e5, sigma=30e-6,
                    displacement=1.0):
    """(the detector, its codes) with the nominal plant's oil and torque balance for a sequence
    of position innovations (m; innovation sigma ``sigma``), the active motor's speeds (rad/s)
    and currents (A); pa, pb: each chamber's reading (Pa, NaN: rejected), one for every
    sample or a list of one per sample; displacement: the learned D_p over the nominal."""
    from eha_ros.core.sim.batch import nominal_params
    p = nominal_params()['estimator']
    det = fd.FaultDetector(1e-3, jump_debounce=3, jump_step=100e-6, jump_pressure_veto=8.0,
                           pd_per_m=fd.pd_per_m(p), torque_balance=fd.torque_balance(p, 1e-3))
    det.start(0.0)
    n = len(innovations)
    pas = pa if isinstance(pa, list) else [pa] * n
    pbs = pb if isinstance(pb, list) else [pb] * n
    return det, [det.update(1e-3 * k, y, sigma ** 2, 0.0, a, b, w, i, displacement)
                 for k, (y, w, i, a, b) in enumerate(zip(innovations, speeds, currents, pas, pbs))]


def test_the_shaft_vetoes_a_jump_when_the_loaded_chambers_sensor_is_lost():
    """Chamber A's sensor below its range while the load compresses A: B sits on its check
    valve and does not move, but the pump's torque reaches the motor shaft within the tick.
    The torque balance (eq. 3.17), p_D = (k_T i - b_eq w - J_eq dw/dt) / D_p, then vetoes the
    jump. Recorded at the 10 kN step of the Table 3.4 sine on the nominal plant (tuning seed
    1): the speed 201.3 -> 199.4 rad/s and the current 0.96 -> 4.63 A on the step's first
    sample, 54 bar of p_D from the shaft; a 1 mm sensor jump: -6.7 bar, the loop's answer two
    samples later."""
    from eha_ros.core.sim.batch import nominal_params
    p = nominal_params()['estimator']
    tb = fd.torque_balance(p, 1e-3)
    k_T, b, J, D_p = (p['plant.motor.k_T'], p['plant.motor.b_eq'], p['plant.motor.J_eq'],
                      p['plant.pump.D_p'])
    assert tb == (k_T, b, J, D_p, 1e-3)
    step = [23e-6, -13e-6, 5e-6, -434e-6, -326e-6, -312e-6, -228e-6, -258e-6]
    load_w = [197.2, 201.1, 201.3, 199.4, 202.8, 238.0, 276.1, 312.0]
    load_i = [0.91, 3.96, 0.96, 4.63, 6.33, 37.84, 35.16, 34.57]
    assert fd.JUMP not in _shaft_codes(step, load_w, load_i)     # the shaft felt the load
    jump = [5e-6, -8e-6, -12e-6, 995e-6, 794e-6, 662e-6, 584e-6, 644e-6]
    jump_w = [1.4, -1.8, -0.9, 1.7, 2.3, -36.1, -78.5, -120.5]
    jump_i = [-1.06, -1.82, 0.88, 1.52, 0.18, -28.91, -35.51, -34.61]
    assert fd.JUMP in _shaft_codes(jump, jump_w, jump_i)         # the shaft did not
    # without a current (none sent, or the speed held): no veto by the shaft, as before
    assert fd.JUMP in _shaft_codes(step, load_w, [math.nan] * 8)
    # both pressures valid: the measured p_D speaks, the shaft is not asked
    assert fd.JUMP in _shaft_codes(step, load_w, load_i, pa=30e5, pb=10e5)


def test_a_10kN_step_on_a_soft_oily_plant_is_no_sensor_jump_with_the_compensation():
    """The run above in the closed loop: random:200 held-out seed 104, plant 17 (C_eq x0.67,
    D_p x0.83, beta x0.69, friction x1.97, noise x1.38, leak split x0.26), motor_fail with the
    leakage compensation at alpha 0.5: a sensor jump was reported 4 ms after the 10 kN step,
    the switch manager took the safe state and the motor failure at 2 s found no couple to
    switch to. Now no fault is reported and the loop ends on couple B."""
    from eha_ros.core.sim import campaign
    from eha_ros.core.sim import closed_loop as CL
    from eha_ros.core.sim import scenarios as SC
    from eha_ros.core.sim.batch import build_loop, nominal_params
    from eha_ros.core.sim.family import plant_params
    from eha_ros.core.sim.switchover import schedule
    mult = dict(C_eq=0.6737856817439098, D_p=0.8287251101937666, beta=0.685323431926731,
                k_T=0.9254206128249296, k_E=1.0229420541109862, friction=1.9710698971564868,
                noise=1.3818715090570264, leak_split=0.2601161296319972)
    scn = SC.load('motor_fail')
    nom = nominal_params(overrides={'controller:control.leakage_compensation': 0.5})
    plant = plant_params(nom['plant_sim'], mult)
    Ts = plant['plant.sim.Ts']
    ref, load, faults, commands = SC.signals(scn, Ts)
    n = len(ref)
    loop = build_loop({**nom, 'plant_sim': plant}, campaign.noise_seed(104, 17),
                      schedule(faults, n, Ts), schedule(commands, n, Ts))
    rec = loop.run(ref, load)
    t = np.arange(n) * Ts
    assert not (rec[t < 2.0, CL.R_FAULT] == fd.JUMP).any()
    assert rec[-1, CL.R_ACTIVE] == 1                  # on couple B after the motor failure


def test_the_shaft_reads_p_d_through_the_displacement_the_estimator_learned():
    """The shaft's torque balance gives p_D through D_p: a pump of D_p x0.8 turns a load's p_D
    into 0.8 of the torque, so with the nominal D_p its p_D reads 20 % short. As on Table 4.5
    held-out seed 104, plant 114 (C_eq x1, D_p x0.8, beta x0.7, k_T x1.2, k_E x0.8),
    `pressure_lost_loaded`, at the 10 kN step, where the estimator had learned delta = -0.207:
    the step's innovation, 630 um, asks for 27.9 bar; a current 2.49 A up on a steady shaft
    is 27.2 bar read with the nominal D_p (a jump: the safe state, the run failed before
    2026-11-30), 34.3 bar with the learned one (vetoed)."""
    y = [0.0] * 20 + [-630e-6, -404e-6, -380e-6, -338e-6, -307e-6, -289e-6]
    w = [250.0] * len(y)
    i = [2.0] * 20 + [2.0 + 2.49] * 6

    def codes(displacement):
        return _shaft_codes(y, w, i, sigma=11.33e-6, displacement=displacement)

    assert fd.JUMP in codes(1.0)                 # the nominal D_p: as before, the safe state
    assert fd.JUMP not in codes(1 - 0.207)       # the learned one: the shaft felt the load


def test_the_shaft_compares_a_run_with_its_mean_before_not_with_one_ripple_sample():
    """The shaft's p_D swings by about 20 bar rms from one tick to the next under the Table 3.4
    sine (mostly at 160 Hz: the drive's current and the speed's one-tick difference), as much
    as a 10 kN step moves it on a soft plant. Recorded on Table 4.5 tuning seed 1, plant 141
    (C_eq x1, D_p x1, beta x0.7, k_T x1.2, k_E x0.8), `pressure_lost_loaded`, 0.96-1.005 s:
    the 10 kN step's innovation, 660 um, asks for 29.2 bar. Against the last sample before
    the run (7.7 bar, a ripple's crest) the shaft moved by 25.6 bar: a jump, the safe state,
    the run failed before 2026-11-30. Against the mean over the 10 ms before (PV_MEAN_TIME,
    -7.1 bar) it moved by 40.4 bar: vetoed."""
    nan = math.nan
    y = [4.33, 4.46, -0.47, -1.12, 18.88, -2.19, -4.17, 11.48, -6.11, -10.5, 12.44, 15.86, 10.39,
         5.44, 4.46, -4.53, 6.98, 19.05, -6.64, 5.69, -19.52, 17.62, -4.05, 6.86, 1.02, -2.66,
         15.53, -8.0, 3.52, -2.17, 16.44, 0.96, 1.37, 29.77, -5.19, 7.55, -23.18, 14.22, -13.92,
         -16.09, 25.47, -635.34, -422.14, -387.34, -354.11, -309.13]
    w = [108.55, 110.357, 110.253, 116.122, 121.951, 126.173, 125.675, 126.86, 134.564, 138.11,
         140.093, 145.603, 146.561, 144.992, 146.355, 151.731, 157.848, 161.841, 162.302, 159.231,
         163.484, 170.555, 176.776, 177.102, 173.115, 175.59, 179.519, 185.187, 185.233, 185.409,
         188.372, 190.244, 190.49, 190.526, 194.526, 193.092, 193.873, 198.591, 203.824, 204.349,
         202.104, 203.551, 201.117, 244.63, 291.862, 336.451]
    i = [2.4396, 1.4416, 0.7437, 3.7959, 3.2702, 2.6735, 0.2795, 1.6532, 4.9145, 1.9737, 1.8492,
         3.5943, 0.9445, 0.0949, 1.8373, 3.5368, 3.693, 2.6892, 0.8654, -0.4394, 3.2992, 4.2814,
         3.8779, 0.5417, -0.6696, 2.4811, 2.78, 3.7486, 0.6966, 1.2398, 2.4454, 2.0614, 0.9364,
         1.236, 3.1277, -0.0737, 1.8686, 3.2616, 3.6248, 1.0341, 0.0529, 5.3708, 2.1916, 38.2073,
         35.2371, 34.7462]
    pb = [9.73, 9.83, 9.53, 9.75, 9.65, 10.0, 9.42, 9.67, 9.84, 9.84, 10.03, 9.09, 9.45, 9.47,
          10.09, 9.83, 10.1, 10.83, 10.01, 10.95, 9.61, 10.58, 9.34, 10.82, 10.93, 10.29, 10.55,
          9.3, 10.95, 9.78, 10.37, 10.24, 10.13, 11.06, 9.78, 11.04, 9.38, 10.53, 10.46, 9.88,
          11.4, nan, 9.86, 7.86, 9.37, 9.01]
    from eha_ros.core.redundancy.health import shaft_pressure
    det, codes = _shaft_detector([v * 1e-6 for v in y], w, i, pb=[v * 1e5 for v in pb],
                                 sigma=11.20e-6, displacement=0.98570)
    assert fd.JUMP not in codes
    # the run's reference: the shaft's p_D of the 40 samples before it, averaged over 10 ms
    k_T, b, J, D_p, Ts = det.k[fd.FK_TB_KT:fd.FK_TS + 1]
    pv = [shaft_pressure(i[k], w[k], (w[k] - w[k - 1]) / Ts, k_T, b, J, D_p * 0.98570)
          for k in range(1, 41)]
    mean = pv[0]
    for v in pv[1:]:
        mean += Ts / fd.PV_MEAN_TIME * (v - mean)
    assert det.s[fd.FS_PVREF] == pytest.approx(mean, rel=1e-12)
    assert mean == pytest.approx(-7.1e5, abs=0.1e5) and pv[-1] == pytest.approx(7.7e5, abs=0.1e5)


@pytest.mark.parametrize('seed, run, D_p', [(104, 114, 0.8), (1, 141, 1.0)])
def test_the_runs_they_were_recorded_on_keep_out_of_the_safe_state(seed, run, D_p):
    """The runs of the two tests above in the closed loop (Table 4.5, plant 114 of held-out
    seed 104 and plant 141 of tuning seed 1, each its own noise; C_eq x1, beta x0.7, k_T
    x1.2, k_E x0.8): the first ended in the safe state on couple A with the shaft read
    through the nominal D_p, the second with the run compared with the last sample before
    it; now no jump is called, the loop stays on A, and the extra deviation is within the
    scenario's 3 mm."""
    from eha_ros.core.sim import campaign
    from eha_ros.core.sim import scenarios as SC
    from eha_ros.core.sim.batch import nominal_params
    mult = dict(C_eq=1.0, D_p=D_p, beta=0.7, k_T=1.2, k_E=0.8, friction=1.0, noise=1.0,
                leak_split=1.0)
    figs, _ = SC.run(SC.load('pressure_lost_loaded'), nominal_params(), mult,
                     campaign.noise_seed(seed, run), trace=False)
    assert figs['safe_state'] == 0 and figs['final_channel'] == 0
    assert figs['extra_deviation_m'] <= 3e-3


# ------------------------------------------------------------------ the family
@pytest.mark.parametrize('scale', [[10, 1, 1, 1, 1], [10, 0.8, 0.7, 1.2, 0.8],
                                   [0.1, 1, 1.4, 0.8, 1.2]])
def test_load_step_holds_on_the_leaky_and_the_tight_corner(scale):
    """Issue 15: leakage x10 ran away at 25 mm/s (-44 mm after 2 s) while the estimate said
    0.00 mm; the opposite corner ended 4 mm off. 5 kN load step while holding 0."""
    s = stack(scale)
    n = 5000
    t = np.arange(n) * 1e-3
    rec = run(s, np.zeros(n), np.where(t >= 0.5, 5e3, 0.0))
    x, xh = rec[:, R_X], rec[:, R_XHAT]
    w = (t >= 4.0) & (t < 5.0)
    peak = np.abs(x[t >= 0.5]).max()
    print(f'\n{scale}: peak {peak * 1e3:.3f} mm, 3.5-4.5 s after the step '
          f'{np.mean(x[w]) * 1e6:.1f} um, estimate {np.mean(xh[w]) * 1e6:.1f} um, '
          f'lambda {s.estimator.kf.leakage_correction:.2f}')
    # the loop closed on the noise-free measured position (no estimator): what the controller
    # alone leaves 3.5-4.5 s after the step (the slow pole near -0.5 rad/s); on the leaky
    # corner that is already 20 um (the linear loop: 14 um), the controller's part (issue 17)
    ref = stack(scale, noise=False)
    ref._loop.est = None
    x_ref = run(ref, np.zeros(n), np.where(t >= 0.5, 5e3, 0.0))[:, R_X]
    print(f'loop on the noise-free position: {np.mean(x_ref[w]) * 1e6:.1f} um')
    assert peak < 0.5e-3
    assert abs(np.mean(x[w])) < max(20e-6, abs(np.mean(x_ref[w])) + 10e-6)
    assert not (rec[:, R_FAULT] == fd.JUMP).any()          # a load step is not a sensor jump
    assert s.estimator.consistency != adapt.DISAGREE


def test_unmodelled_flow_opens_only_on_a_held_load_and_is_bounded_by_its_leak():
    """adapt.flow_noise: the walk opens after n_open updates at rest with |b| beyond its gate
    and the pressure difference steady (within dp_fric); under a sinusoidal load it never opens
    (it did, and chased the reversing flows: Table 4.5 plant 213, C_eq x3.16, beta x1.4, lost
    its 7 Hz stiffness, 72 -> 21 kN/mm); without a load its bound is zero; it reports (True)
    while |v_f| > v_report."""
    fk = np.zeros(adapt.NFK)
    fk[adapt.FK_CX], fk[adapt.FK_CR], fk[adapt.FK_AP] = 1e-15, 2e-15, 1e-3
    i_gm, i_flow, n_open, dp_fric, b_sigma = 5, 6, 100, 0.74e6, 20e-6

    def hold(dps, b=100e-6, v=0.0, rest=True):
        x, Q, count = np.zeros(7), np.zeros((7, 7)), np.zeros(adapt.NFLOW)
        opened, reported = [], []
        for dp in dps:
            x[2], x[3], x[i_gm], x[i_flow] = 5e6 + dp, 5e6, b, v
            reported.append(adapt.flow_noise(Q, x, i_flow, i_gm, b_sigma, 3.0, 1e-9, rest,
                                             count, n_open, fk, dp_fric, 1.0, 2e-5))
            opened.append(Q[i_flow, i_flow] > 0)
            v = x[i_flow]
        return np.array(opened), np.array(reported), v

    k = np.arange(1000)
    opened, _, _ = hold(np.full(1000, 5e6) + 1e4 * np.sin(k))       # held 5 MPa, noisy
    assert not opened[:n_open - 1].any() and opened[n_open:].all()
    assert not hold(np.full(1000, 5e6), b=50e-6)[0].any()            # b within its gate
    assert not hold(np.full(1000, 5e6), rest=False)[0].any()         # the piston moves
    assert not hold(5e6 * np.sin(2 * np.pi * 7 * k * 1e-3))[0].any()  # 7 Hz load: never
    # the bound: (C_x + C_r)(|dp| - dp_fric)/A_p; 5 MPa: 12.8 um/s, so 1 mm/s is clipped
    _, reported, v = hold(np.full(10, 5e6), v=1e-3)
    assert v == pytest.approx(3e-15 * (5e6 - dp_fric) / 1e-3)
    assert not reported.any()                                        # 12.8 < 20 um/s
    fk[adapt.FK_CX] = 10e-15                                         # a leakier model
    _, reported, v = hold(np.full(10, 5e6), v=1e-3)
    assert v > 2e-5 and reported.all()
    _, reported, v = hold(np.full(10, 0.5e6), v=1e-3)                # no load: no leak
    assert v == 0.0 and not reported.any()


def test_unmodelled_flow_holds_a_leak_the_adaptive_states_cannot_split():
    """Issue 15, plant 193 of random:200 (seed 1): C_eq x3.2 with the external leakage x1.85
    of its share. Holding 5 kN, the adaptive leakage/displacement/compliance states cannot be
    told apart at one operating point; without the unmodelled-flow state (adapt.flow_noise)
    the estimate drifts from the truth while the sensor offset state b takes the innovation
    (b at 9 sigma of its Gauss-Markov model). Campaign load_step figure: mean |x| 3.5-4.5 s
    after the step. The drift needs a particular noise realization: on noise seeds 1-8 it
    came on seeds 4 and 7 (52 and 124 um; with the flow state 27 and 21 um), the others are
    the same with and without (6-29 um). Seed 7 here; before the filter started at rest
    (ChamberKF.reset) it was seed 1, 164 um against 0.9 um."""
    from eha_ros.core.sim import campaign, scenarios
    nominal = campaign.nominal_params()
    # the estimate itself: the published position stays x_hat at rest under the load (the
    # decided steady error is against the sensor, whose offset the loop then holds: issue 42)
    nominal['estimator'] = without(nominal['estimator'], 'hold_blend')
    row = dict(C_eq=3.186, D_p=0.926, beta=0.993, k_T=0.866, k_E=1.119, friction=1.048,
               noise=1.050, leak_split=1.848)
    scn = scenarios.load('load_step')
    with_flow = scenarios.run(scn, nominal, row, 7, trace=False)[0]['steady_error_truth_m']
    nominal['estimator'] = without(nominal['estimator'], 'flow_state')
    no_flow = scenarios.run(scn, nominal, row, 7, trace=False)[0]['steady_error_truth_m']
    print(f'\nsteady error with the flow state {with_flow * 1e6:.1f} um, '
          f'without {no_flow * 1e6:.1f} um')
    assert no_flow > 100e-6
    assert with_flow < 25e-6


def test_the_hold_blend_judges_motion_on_the_pump_flow_velocity_over_rest_time():
    """stepper.hold_blend, the weight of b in the published position, fed the 50 Hz pump-flow
    velocity directly (rest_velocity 3 mm/s, rest_time 0.1 s, hold_blend_time 0.2 s)."""
    from eha_ros.core.estimator import stepper
    K, E = stepper.new_records()
    k, e = K[0], E[0]
    k['friction'][adapt.FK_VREST], k['friction'][adapt.FK_NREST] = 3e-3, 100
    k['hold_rate'] = 1 / 200

    def weights(v, loaded):
        E[0] = np.zeros(1, stepper.STATE)[0]
        out = []
        for vk, lk in zip(v, np.broadcast_to(loaded, v.shape)):
            e['friction'][adapt.FS_V] = vk
            stepper.hold_blend(e, k, bool(lk))
            out.append(e['hold_weight'])
        return np.array(out)

    t = np.arange(2000) * 1e-3
    # a held load, the piston still, speed noise beyond rest_velocity on a third of the ticks
    noisy = np.random.default_rng(1).normal(0.0, 3e-3, t.size)
    w = weights(noisy, True)
    assert np.mean(np.abs(noisy) > 3e-3) > 0.3
    assert w[400:].min() == 1.0
    # the 3 Hz, 3 mm sine under 10 kN (switch, motor_fail, pressure_*): never blended in
    assert weights(57e-3 * np.cos(2 * np.pi * 3 * t), True).max() == 0.0
    # the piston moves off at 10 mm/s under the held load: out after rest_time + the blend
    w = weights(np.where(t < 1.0, noisy, 10e-3), True)
    assert w[999] == 1.0 and w[t >= 1.5].max() == 0.0
    # the load lets go: out over hold_blend_time
    w = weights(noisy, t < 1.0)
    assert w[999] == 1.0 and w[t >= 1.2].max() == 0.0


def test_the_hold_blend_stays_in_while_speed_noise_crosses_rest_velocity():
    """Issue 42, load_step on random:200, tuning seeds 1 and 2: 20 of the 24 failures were the
    steady error against the sensor (20-98 um). The hold blend waited for the Stribeck input's
    rest: the pump-flow velocity from the measured motor speed (low-passed at 50 Hz) below
    rest_velocity (3 mm/s) for rest_time, and blended b out on every tick it was not. With
    the speed sensor's noise at x1.2-2 it crosses 3 mm/s every few tens of ms: weight
    0.36-0.64 over 3.5-4.5 s after the step, 0.03-0.05 where the leakage model is off and
    v_f open (the velocity's mean -2 mm/s). The blend now judges that velocity averaged over
    rest_time (stepper.hold_blend). Seed 1 plant 55 (friction x1.8, noise x1.93): 28.8 um
    before, 1.9 um now; seed 2 plant 154 (C_eq x6.5, the external leakage x1.96 of its
    share): 98.3 um before (b took the truth's drift, the truth 89 um off), 1.2 um now."""
    from eha_ros.core.sim import campaign, scenarios
    nominal = campaign.nominal_params()
    scn = scenarios.load('load_step')
    for row, seed in ((dict(C_eq=0.246, D_p=0.958, beta=1.034, k_T=1.002, k_E=1.071,
                            friction=1.808, noise=1.928, leak_split=1.051),
                       4109706526811917959),
                      (dict(C_eq=6.463, D_p=1.026, beta=1.415, k_T=1.21, k_E=0.879,
                            friction=0.949, noise=1.193, leak_split=1.958),
                       5667862900036411438)):
        figs = scenarios.run(scn, nominal, row, seed, trace=False)[0]
        print(f'\nC_eq x{row["C_eq"]}: steady error against the sensor '
              f'{figs["steady_error_m"] * 1e6:.1f} um, the truth\'s '
              f'{figs["steady_error_truth_m"] * 1e6:.1f} um')
        assert figs['steady_error_m'] < 10e-6


LOAD_T = np.arange(6000) * 1e-3


def load_flags(dp, noise=None):
    """Per update, in the compiled estimate step's order (stepper.estimate, consistency):
    adapt.load_swinging on the previous mean, adapt.load_variation, then load_varying.
    ``dp``: the pressure difference beyond 5 MPa (Pa), Ts 1 ms; the stack's bands (the 0.74
    MPa friction holds; LOAD_SWING_BAND x it) and offset_load_mean's default (0.25 s)."""
    Ts, dp_friction = 1e-3, 0.74e6
    alphas = (Ts / 0.25, Ts / adapt.LOAD_VARIANCE_TIME)
    hold = round(adapt.LOAD_SWING_HOLD / Ts)
    x, lv = np.zeros(6), np.zeros(adapt.NLV)
    varying, swinging = np.zeros(dp.size, bool), np.zeros(dp.size, bool)
    for k in range(dp.size):
        x[2], x[3] = 5e6 + dp[k] + (0.0 if noise is None else noise[k]), 5e6
        swinging[k] = adapt.load_swinging(x, lv, adapt.LOAD_SWING_BAND * dp_friction, hold)
        adapt.load_variation(x, lv, *alphas)
        varying[k] = adapt.load_varying(lv, dp_friction)
    return varying, swinging


def test_load_variation_tells_a_varying_load_from_a_held_one():
    """adapt.load_variation / load_varying (the varying load of disagree_noise's q_x_offset,
    which also keeps the unmodelled flow v_f closed): a 1 Hz 5 kN load (2 MPa) is varying once
    the variance has built up; a 5 kN load step, held, and its removal never are (a step adds
    at most 1/16 of its square), nor is no load."""
    t = LOAD_T
    noise = 2e4 * np.random.default_rng(1).standard_normal(t.size)

    def varying(dp):
        return load_flags(dp, noise)[0]

    sine = varying(1.94e6 * np.sin(2 * np.pi * t))
    print(f'\n1 Hz 5 kN load: varying after {t[np.argmax(sine)]:.2f} s')
    assert not sine[:500].any() and sine[t > 2.0].all()
    step = np.where(t >= 1.0, 1.94e6, 0.0)
    assert not varying(step).any() and not varying(step[::-1]).any()
    assert not varying(np.zeros(t.size)).any()


def test_load_swinging_holds_through_a_sinusoidal_load_not_a_step_nor_friction_flips():
    """adapt.load_swinging (the position noise q_x_offset while the load swings): a 1 Hz 5 kN
    load (2 MPa) swings from its first full swing on (beyond the band above and below its
    mean) and holds through every crossing of its mean (LOAD_SWING_HOLD); a 5 kN step, its
    removal, friction's flips under a sine without load (a 0.5 MPa square wave: about
    friction x2) and no load never swing.
    The band is the stack's: LOAD_SWING_BAND x the 0.74 MPa friction holds."""
    t = LOAD_T

    def swinging(dp):
        return load_flags(dp)[1]

    sine = swinging(1.94e6 * np.sin(2 * np.pi * t))
    first = t[np.argmax(sine)]
    print(f'\n1 Hz 5 kN load: swinging from {first:.3f} s on')
    assert 0.4 < first < 0.6 and sine[t >= first].all()
    step = np.where(t >= 1.0, 1.94e6, 0.0)
    assert not swinging(step).any() and not swinging(step[::-1]).any()
    assert not swinging(0.5e6 * np.sign(np.sin(2 * np.pi * t))).any()
    assert not swinging(np.zeros(t.size)).any()


def test_position_noise_under_a_swinging_load_keeps_the_stiffness_without_an_alarm():
    """Campaign scenario stiffness on a C_eq x10 corner of Table 4.5 (D_p x0.8, beta x0.7, k_T
    x0.8, k_E x1.2; tuning seed 4's run 2). With the position noise at q_x while the load
    swings, the sensor offset state b takes the adaptive states' error in the first negative
    half-wave (they are still learning the leakage): filter_sensor_disagree 0.66 s in, and the
    1 Hz stiffness far under its limit. With
    q_x_offset from the load's first full swing on (adapt.disagree_noise, adapt.swinging) the
    estimate follows the sensor at low frequency: no sample alarmed, every limit met.
    (The force state's walk while the load swings, estimator.model.q_load_swing of 01c4391,
    was removed: with this it moved no pass count, see docs/nodes/estimator.md.)"""
    from eha_ros.core.sim import campaign, scenarios
    from eha_ros.core.sim.batch import build_loop
    from eha_ros.core.sim.family import plant_params
    from eha_ros.core.sim.closed_loop import R_X0
    row = dict(GRID, C_eq=10.0, D_p=0.8, beta=0.7, k_T=0.8, k_E=1.2)
    nominal = campaign.nominal_params()
    scn = scenarios.load('stiffness')
    limits = campaign.plant_limits(scn, row, nominal)[0]
    plant = plant_params(nominal['plant_sim'], row)
    Ts = plant['plant.sim.Ts']
    ref, load, _, _ = scenarios.signals(scn, Ts)
    est = nominal['estimator']
    res = {}
    for q in (est['estimator.model.q_x_offset'], est['estimator.model.q'][0]):
        params = dict(nominal, plant_sim=plant,
                      estimator=dict(est, **{'estimator.model.q_x_offset': q}))
        loop = build_loop(params, campaign.noise_seed(4, 2))
        rec, alarms = [], 0
        for k in range(0, len(ref), 20):
            rec.append(loop.run(ref[k:k + 20], load[k:k + 20], k0=k))
            alarms += adapt.alarm(loop.est.consistency)
        sig = dict(t=np.arange(len(ref)) * Ts, load=load, truth=np.vstack(rec)[:, R_X0])
        f = scenarios.FIGURES['stiffness'](sig, scn.params, Ts)
        res[q] = alarms, {m: f[m] / limits[m][1] for m in limits}
    on, off = (res[q] for q in res)
    print(f'\nalarmed samples (of 20 ticks) / stiffness over its limit at 1/4/7 Hz: with '
          f'q_x_offset {on[0]} / {"/".join(f"{v:.3f}" for v in on[1].values())}, at q_x '
          f'{off[0]} / {"/".join(f"{v:.3f}" for v in off[1].values())}')
    assert off[0] > 0 and min(off[1].values()) < 1.0
    assert on[0] == 0 and min(on[1].values()) >= 1.0


def test_no_estimator_alarm_under_a_swinging_load_on_the_leaky_plants():
    """Campaign scenario stiffness (5 kN at 1, 4, 7 Hz, position held) on the 108 plants of
    Table 4.5 with C_eq x3.16 and x10, tuning seed 1: no sample alarmed (filter_sensor_disagree
    or sensor_fault) with the estimator's defaults; the code before raised
    filter_sensor_disagree 0.7-1.2 s in on 10 of them, while the adaptive states were still
    learning the leakage and the sensor offset took their error. Without the position noise
    under a varying or swinging load (q_x_offset = q_x, adapt.disagree_noise) 13 are alarmed."""
    from eha_ros.core.sim import campaign, family, scenarios
    from eha_ros.core.sim.batch import build_loop
    from eha_ros.core.sim.closed_loop import R_VERDICT
    nominal = campaign.nominal_params()
    fam = family.thesis()
    scn = scenarios.load('stiffness')
    ids = [i for i, c in enumerate(fam['C_eq']) if c > 3.0]
    est = nominal['estimator']

    def alarmed(est):
        runs = []
        for rid in ids:
            p = family.plant_params(nominal['plant_sim'], {c: float(fam[c][rid]) for c in fam})
            ref, load, _, _ = scenarios.signals(scn, p['plant.sim.Ts'])
            loop = build_loop(dict(nominal, plant_sim=p, estimator=est),
                              campaign.noise_seed(1, rid))
            verdicts = np.unique(loop.run(ref, load)[:, R_VERDICT])
            if any(adapt.alarm(int(v)) for v in verdicts):
                runs.append(rid)
        return runs
    closed = alarmed(dict(est, **{'estimator.model.q_x_offset': est['estimator.model.q'][0]}))
    on = alarmed(est)
    print(f'\n{len(ids)} plants: alarmed runs {on}; with q_x_offset = q_x {closed}')
    assert len(ids) == 108 and on == [] and len(closed) >= 5


def test_the_filter_starts_at_rest_so_a_rising_load_is_not_taken_for_friction(monkeypatch):
    """ChamberKF.reset: the filter starts at rest (its velocity 0; adapt.friction_input's rest
    count full, the held friction 0, the force state's walk at q_load_rest). The stiffness
    scenario's 5 kN at 1 Hz rises from the first tick; on the softest corner (tuning seeds 1-5,
    run 0) the friction scale phi stays within 0.3 of 0 for the first 50 ms (the family's
    friction is Table 3.7's: phi = 0). Counting rest_time first, as before, left the rising
    load to phi: up to +0.83 at 50 ms (seed 3; +0.92 at 0.3 s and filter_sensor_disagree at
    0.8 s)."""
    from eha_ros.core.sim import campaign, scenarios
    from eha_ros.core.sim.batch import build_loop
    from eha_ros.core.sim.family import plant_params
    nominal = campaign.nominal_params()
    p = plant_params(nominal['plant_sim'], dict(GRID, C_eq=10.0, D_p=0.8, beta=0.7, k_T=0.8,
                                                 k_E=0.8))
    ref, load, _, _ = scenarios.signals(scenarios.load('stiffness'), p['plant.sim.Ts'])
    reset = ChamberKF.reset

    def counting(self, *a, **k):                  # the start before: the rest count at 0
        reset(self, *a, **k)
        self.fs[adapt.FS_N] = 0.0

    def phi_at_50ms():
        out = []
        for seed in range(1, 6):
            loop = build_loop(dict(nominal, plant_sim=p), campaign.noise_seed(seed, 0))
            loop.run(ref[:50], load[:50], k0=0)
            out.append(loop.est.kf.x[loop.est.kf.i_friction])
        return np.array(out)
    at_rest = phi_at_50ms()
    monkeypatch.setattr(ChamberKF, 'reset', counting)
    before = phi_at_50ms()
    print(f'\nphi at 50 ms, seeds 1-5: started at rest {np.round(at_rest, 2)}, '
          f'counting rest_time first {np.round(before, 2)}')
    assert np.abs(at_rest).max() < 0.35 and np.abs(before).max() > 0.6


GRID = dict(friction=1.0, noise=1.0, leak_split=1.0)     # Table 4.5: the datasheet's


@pytest.mark.parametrize('row, needed', [     # Table 4.5 plants 211 and 216 (the grid's values)
    (dict(GRID, C_eq=10 ** 0.5, D_p=1.0, beta=1.4, k_T=0.96 ** 0.5, k_E=0.96 ** 0.5), True),
    (dict(GRID, C_eq=10.0, D_p=0.8, beta=0.7, k_T=0.8, k_E=0.8), True)])   # the softest corner
def test_position_noise_under_a_varying_load_keeps_the_stiffness(row, needed):
    """Campaign scenario stiffness (5 kN at 1, 4, 7 Hz) against the decided bound of issue 42
    (49 kN/mm; at the softest corner, whose loaded leakage is beyond Table 4.5, 0.9 x the
    linear loop at that leakage: campaign.plant_limits). With the position noise at q_x's value
    under the varying load the sensor offset state b takes the piston's motion at low
    frequency while the loop holds the estimate: the softest corner misses at 1 Hz (0.66 of its
    limit). With q_x_offset (adapt.disagree_noise) the estimate follows the sensor at low
    frequency: the softest corner, whose loop on the true position reaches only 1.15 / 1.11 /
    1.07 of its limit, 1.04 / 1.02 / 1.03. Plant 211 (beta x1.4) missed without it too (0.55 at
    7 Hz) until the chamber filter's check valves stopped passing reverse flow
    (stepper.valve_state): then 2.1 / 2.9 / 1.7 without, 3.1 / 2.8 / 2.7 with. With the
    leakage compensation (control.leakage_compensation 0.5, the default since 2026-11-29) the
    pump also supplies the leak flow the filter estimates, and plant 211 needs it again: 1.85
    / 2.08 / 0.40 without, 4.67 / 4.03 / 3.83 with; the softest corner 0.84 / 1.21 / 2.20
    without, 1.46 / 1.36 / 1.31 with."""
    from eha_ros.core.sim import campaign, scenarios
    nominal = campaign.nominal_params()
    scn = scenarios.load('stiffness')
    limits = campaign.plant_limits(scn, row, nominal)[0]
    res = {}
    on = nominal['estimator']['estimator.model.q_x_offset']
    for q in (on, nominal['estimator']['estimator.model.q'][0]):
        nominal['estimator'] = dict(nominal['estimator'], **{'estimator.model.q_x_offset': q})
        f = scenarios.run(scn, nominal, row, 1, trace=False)[0]
        res[q] = {m: f[m] / limits[m][1] for m in limits}
    off = next(q for q in res if q != on)
    print(f'\n{row}: stiffness over its limit at 1/4/7 Hz with the position noise open under '
          f'the varying load {"/".join(f"{v:.2f}" for v in res[on].values())}, without '
          f'{"/".join(f"{v:.2f}" for v in res[off].values())}')
    assert (min(res[off].values()) < 1.0) == needed
    assert min(res[on].values()) >= 1.0


@pytest.mark.parametrize('scale', [[1, 1, 1, 1, 1], [10, 0.8, 0.7, 1.2, 0.8]])
def test_sensor_drift_under_load_is_reported_then_an_alarm_when_the_load_goes(scale):
    """Holding 5 kN, a 1 mm/s position-sensor drift is what a leak of C_eq x1.4 looks like
    (the family's leakage reaches x15): one position sensor cannot tell them apart, v_f takes
    it and the piston follows the sensor. It is never silent (adapt.flow_noise): reported as
    model_mismatch within 0.5 s; once the load goes (no pressure difference, so no leak) the
    drift is filter/sensor disagreement. The compiled path, its verdict read every 10 ms."""
    from eha_ros.core.sim.switchover import schedule
    Ts, n = 1e-3, 5000
    t = np.arange(n) * Ts
    faults = schedule([(2.0, ('msp_drift', 0, 1e-3, 0.0))], n, Ts)
    loads = np.where((t >= 0.5) & (t < 3.5), 5e3, 0.0)
    for drift in (False, True):
        s = stack(scale, faults=faults if drift else None)
        verdicts = np.zeros(n, int)
        for k in range(0, n, 10):
            s._loop.run(np.zeros(10), loads[k:k + 10], k0=k)
            verdicts[k:k + 10] = s.estimator.consistency
        if not drift:            # the same load without the drift: nothing to report
            assert not verdicts.any(), np.unique(verdicts)
            continue
        assert not verdicts[t < 2.0].any()
        model = np.nonzero((t >= 2.0) & (verdicts == adapt.MODEL))[0]
        alarm = np.nonzero((t >= 3.5) & (verdicts == adapt.DISAGREE))[0]
        print(f'\n{scale}: model_mismatch {t[model[0]] - 2.0:.3f} s after the drift starts, '
              f'filter_sensor_disagree {t[alarm[0]] - 3.5:.3f} s after the load goes')
        assert model.size and t[model[0]] - 2.0 <= 0.5
        assert (verdicts[model[0]:3500] != adapt.OK).all()     # reported while it lasts
        assert alarm.size and t[alarm[0]] - 3.5 <= 1.0


def test_displacement_x0_8_step_reaches_the_target():
    """Issue 15: D_p x0.8, a 5 mm step ended 0.5-0.8 mm short while the estimate said 5.000."""
    s = stack([1, 0.8, 1, 1, 1])
    n = 1600
    t = np.arange(n) * 1e-3
    rec = run(s, np.where(t >= 0.1, 5e-3, 0.0))
    x = rec[:, R_X]
    w = (t >= 1.1) & (t < 1.6)
    print(f'\nD_p x0.8: overshoot {(x.max() - 5e-3) / 5e-5:.2f} %, steady '
          f'{(np.mean(x[w]) - 5e-3) * 1e6:.1f} um, delta '
          f'{s.estimator.kf.displacement_correction:+.3f}')
    assert abs(np.mean(x[w]) - 5e-3) < 20e-6
    # the overshoot (6.3 % here) is the controller's: the drive saturates on voltage below the
    # 838 rad/s clamp the anti-windup knows (issue 17); with the truth fed back it is the same


def test_estimate_stays_near_the_sensor_beyond_the_adaptation_range():
    """Leakage x40 (both leakage paths 40 x nominal: the largest total leakage the adaptive
    states reach, (1 + 30.4) C_x + (1 + 36.5) C_r, is 35 x), 5 kN load step: the model cannot
    follow. With a parameter on its bound the position noise opens and the offset is held to
    its sigma (adapt.disagree_noise), so the estimate stays near the sensor, the loop holds on
    it, and the monitor reports it (MODEL / DISAGREE) -- loud, not a silent runaway. (Held
    within 0.55 mm; the pump then runs at 670 of its 838 rad/s to feed the leakage. x60 would
    need 1000 rad/s: no actuator of this family can hold that. |z - x_hat| after 0.6 s: 390 um
    with R at the datasheet, 411 um with the measured noise level, which reads the pump's
    pressure ripple here as 3 % more pressure noise.)"""
    s = stack([40, 1, 1, 1, 1])
    n = 3000
    t = np.arange(n) * 1e-3
    rec = run(s, np.zeros(n), np.where(t >= 0.5, 5e3, 0.0))
    x, xh, xm = rec[:, R_X], rec[:, R_XHAT], rec[:, R_XM]
    kf = s.estimator.kf
    late = t > 0.6
    print(f'\nC_eq x40: max |x| {np.abs(x).max() * 1e3:.3f} mm '
          f'({np.abs(x[t > 2.0]).max() * 1e3:.3f} '
          f'after 2 s), max |z - x_hat| after 0.6 s {np.abs(xm - xh)[late].max() * 1e6:.0f} um, '
          f'lambda {kf.leakage_correction:.2f}, epsilon {kf.external_leakage_correction:.2f}, '
          f'edge {kf.edge}, verdict {adapt.VERDICTS[s.estimator.consistency]}')
    assert np.abs(xm - xh)[late].max() < 0.45e-3
    assert np.abs(x[t > 2.0]).max() < 0.6e-3
    assert (kf.edge or kf.leakage_correction > kf.leakage_range[1] - 1.5 or   # a leakage path
            kf.external_leakage_correction > kf.external_leakage_range[1] - 1.5)  # near its edge
    assert s.estimator.consistency in (adapt.MODEL, adapt.DISAGREE)


# ------------------------------------------------------------------ faults vs mismatch
@pytest.mark.parametrize('scale', [[1, 1, 1, 1, 1], [10, 0.8, 0.7, 0.8, 1.2],
                                   [0.1, 1, 1.4, 1.2, 0.8]])
@pytest.mark.parametrize('fault,code', [(('msp_bias', 0, 1e-3, 0.0), fd.JUMP),
                                        (('msp_stuck', 0, 0.0, 0.0), fd.STUCK)])
def test_sensor_fault_detected_isolated_and_told_from_mismatch(scale, fault, code):
    """1 mm bias / stuck sensor at 2 s during the 1 Hz 5 mm sine: reported within 50 ms as
    a sensor fault; the estimator isolates the sensor (predict-only on the adapted model), so
    the piston does not follow the faulty reading, and the controller goes to the safe state
    (core.loop.safe_state: zero speed; no switch manager here, so no valve lock)."""
    s = stack(scale, seed=3, faults={2000: [fault]})
    n = 2300
    t = np.arange(n) * 1e-3
    ref = 5e-3 * np.sin(2 * np.pi * t)
    rec = run(s, ref)
    codes = rec[:, R_FAULT]
    hit = np.nonzero((t >= 2.0) & (codes != 0))[0]
    assert not codes[t < 2.0].any()
    assert hit.size and codes[hit[0]] == code
    delay = t[hit[0]] - 2.0
    err = np.abs(rec[:, R_X] - ref)
    before, after = err[(t >= 1.0) & (t < 2.0)].max(), err[t >= 2.0].max()
    print(f'\n{scale} {fault[0]}: detected after {delay * 1e3:.0f} ms; tracking error '
          f'{before * 1e6:.0f} um before, {after * 1e6:.0f} um in the 0.3 s after; verdict '
          f'{adapt.VERDICTS[s.estimator.consistency]}')
    assert delay <= 0.050
    assert s.estimator.consistency == adapt.SENSOR and s.estimator.safe_state_required
    u, x = rec[:, R_U], rec[:, R_X]
    held = np.nonzero((t >= 2.0) & (u == 0.0))[0]
    assert held.size and np.all(u[held[0]:] == 0.0) and t[held[0]] - 2.0 <= 0.050
    assert s._loop.holding
    # isolated, then held: the piston neither follows the bad reading nor keeps moving
    assert err[(t >= 2.0) & (t <= t[held[0]])].max() < before + 0.1e-3
    assert np.abs(x[held[0]:] - x[held[0]]).max() < 0.3e-3
    print(f'safe state {(t[held[0]] - 2.0) * 1e3:.0f} ms after the fault; piston moved '
          f'{np.abs(x[held[0]:] - x[held[0]]).max() * 1e6:.0f} um after it')


@pytest.mark.parametrize('scale', [[1, 1, 1, 1, 1], [10, 0.8, 0.7, 0.8, 1.2]])
def test_a_sensor_jump_under_a_swinging_load_is_not_followed(scale):
    """Reference held at 0 under a 5 kN 1 Hz sinusoidal load, the position sensor jumps by
    1 mm at 2 s (found 2026-11-26, docs/nodes/estimator.md). The varying load opens the
    position's process noise (adapt.disagree_noise) and the gain took 78 % of the jump on its
    first sample: the innovation fell under the jump threshold before the debounce's third
    sample, no fault was reported and the loop moved the piston by the bias (-1 mm). The
    samples of a suspected jump are not taken until the debounce decides
    (fault_detector.suspect): the jump is detected, the safe state follows, and the piston
    stays where it was."""
    s = stack(scale, seed=7, faults={2000: [('msp_bias', 0, 1e-3, 0.0)]})
    n = 2300
    t = np.arange(n) * 1e-3
    rec = run(s, np.zeros(n), 5e3 * np.sin(2 * np.pi * t))
    codes, x = rec[:, R_FAULT], rec[:, R_X]
    hit = np.nonzero((t >= 2.0) & (codes != 0))[0]
    assert not codes[t < 2.0].any()
    assert hit.size and codes[hit[0]] == fd.JUMP
    held = np.nonzero((t >= 2.0) & (rec[:, R_U] == 0.0))[0]
    swing = np.abs(x[(t >= 1.0) & (t < 2.0)]).max()       # the load's own motion
    moved = np.abs(x[(t >= 2.0) & (t <= t[held[0]])]).max() if held.size else math.inf
    print(f'\n{scale}: jump detected after {(t[hit[0]] - 2.0) * 1e3:.0f} ms, safe state '
          f'{(t[held[0]] - 2.0) * 1e3 if held.size else math.inf:.0f} ms; piston within '
          f'{swing * 1e6:.0f} um before, {moved * 1e6:.0f} um until held; '
          f'{s.estimator.detector.suspect_samples} suspect samples')
    assert t[hit[0]] - 2.0 <= 0.005
    assert s.estimator.consistency == adapt.SENSOR and t[held[0]] - 2.0 <= 0.050
    assert moved < swing + 50e-6


@pytest.mark.parametrize('force', [0.0, 5e3])
def test_a_two_sample_glitch_is_not_followed_nor_a_fault(force):
    """The sensor reads 1 mm off for two samples (2.000-2.002 s), nominal plant, reference
    held at 0, with and without the 5 kN 1 Hz load. Its samples are a suspected jump's: not
    taken, and not a jump, since the third sample is back. Before, under the load the
    estimate followed the glitch by 0.94 mm, the loop moved the piston by 0.54 mm and a jump
    was reported, then the safe state; without it the estimate's 74 um pull ended in a jump
    and a drift report."""
    s = stack([1, 1, 1, 1, 1], seed=7, faults={2000: [('msp_bias', 0, 1e-3, 0.0)],
                                               2002: [('msp_bias', 0, 0.0, 0.0)]})
    n = 3000
    t = np.arange(n) * 1e-3
    rec = run(s, np.zeros(n), force * np.sin(2 * np.pi * t))
    err = np.abs(rec[:, R_XHAT] - rec[:, R_X])
    before, after = err[(t >= 1.0) & (t < 2.0)].max(), err[t >= 2.0].max()
    print(f'\n{force:.0f} N: estimate error {before * 1e6:.0f} um before, {after * 1e6:.0f} um '
          f'after; {s.estimator.detector.suspect_samples} suspect samples')
    assert not rec[:, R_FAULT].any() and s.estimator.consistency == adapt.OK
    assert s.estimator.detector.suspect_samples == 2
    assert s.estimator.updates == n - 1 - 2        # the first sample starts it; 2 held back
    # published as predict only: no update behind them (nis_dim 0, update_skipped), on the
    # records whose measured position carries the bias (2001-2002) and no other
    assert list(np.nonzero(rec[1:, R_NISDIM] == 0)[0] + 1) == [2001, 2002]
    assert list(np.nonzero(rec[:, R_SKIP])[0]) == [2001, 2002]
    assert after < before + 20e-6
    # with the isolate stage off the samples are taken: none held back, none counted
    s = stack([1, 1, 1, 1, 1], seed=7, faults={2000: [('msp_bias', 0, 1e-3, 0.0)],
                                               2002: [('msp_bias', 0, 0.0, 0.0)]},
              est={'estimator.stages': [g for g in DEFAULT_STAGES if g != 'isolate']})
    run(s, np.zeros(n), force * np.sin(2 * np.pi * t))
    assert s.estimator.detector.suspect_samples == 0 and s.estimator.updates == n - 1


def test_monitor_verdicts_hold_and_severity():
    mk = np.array([1.0, 1e-4, 2.0, 3.0])          # no low-pass, band 0.1 mm, 2 samples, hold 3
    ms = np.zeros(adapt.NMS)
    step = lambda d, code=0, drift=False, edge=0: adapt.monitor(mk, ms, d, 0.0, code, drift, edge)
    assert step(0.0) == adapt.OK
    assert step(0.0, drift=True) == adapt.MODEL
    assert step(2e-4) == adapt.MODEL and step(2e-4) == adapt.DISAGREE
    assert step(0.0, drift=True) == adapt.DISAGREE      # a milder verdict does not replace it
    assert step(0.0, code=fd.STUCK) == adapt.SENSOR
    assert [step(0.0) for _ in range(4)] == [adapt.SENSOR, adapt.SENSOR, adapt.OK, adapt.OK]
    # a jump alone (a load step can pass for one) is not a sensor fault; with the
    # disagreement it is
    assert step(0.0, code=fd.JUMP) == adapt.OK
    assert step(2e-4, code=fd.JUMP) == adapt.OK and step(2e-4, code=fd.JUMP) == adapt.SENSOR
    assert adapt.safe_state(adapt.SENSOR) and not adapt.safe_state(adapt.DISAGREE)
    assert adapt.alarm(adapt.SENSOR) and adapt.alarm(adapt.DISAGREE)
    assert not adapt.safe_state(adapt.MODEL) and not adapt.alarm(adapt.MODEL)


# ------------------------------------------------------------------ tuning
def test_tuned_table_holds_the_tuning_derived_from_the_family(params):
    """The TUNED table the estimator reads (adaptive_prior) carries what scripts/tune_estimator
    derives from config/qft_spec.yaml's family and the random box (4 digits)."""
    from eha_ros.core.estimator.params import TUNED
    from eha_ros.tools import tune_estimator as T
    from eha_ros.core.qft.spec import load_spec
    spec = load_spec(os.path.join(ROOT, 'config', 'qft_spec.yaml'))
    fam = {n: tuple(spec[f'family.{n}_range']) for n in ('C_eq', 'D_p', 'beta', 'k_T', 'k_E')}
    inp = tuning.Inputs(family=fam, C_x=params['plant.pump.C_p'] + params['plant.cylinder.C_c'],
                        C_r=params['plant.pump.C_r'])
    for key, v in tuning.derive(inp)['values'].items():
        want = [float(T.fmt(a)) for a in v] if isinstance(v, list) else float(T.fmt(v))
        assert TUNED[key] == pytest.approx(want, rel=1e-12), key


def test_sensor_bands_follow_the_sensor_model(params):
    """The offset bound, DISAGREE band and jump step come from plant.sensors at run time: the
    datasheet's 10 um white and 20 um Gauss-Markov sensor gives the values tune_estimator
    wrote before (253, 214, 141 um), a sensor twice as noisy bands twice as wide, and the
    noise scale is the random box's largest."""
    from eha_ros.core.estimator import sensor_band as SB
    from eha_ros.core.qft.family_box import load_box
    b = SB.from_params(params)
    assert (b.offset_bound, b.band, b.jump_step) == pytest.approx((2.532e-4, 2.1362e-4,
                                                                    1.4142e-4), rel=2e-4)
    assert SB.NOISE_SCALE == load_box()['noise'][1]
    from eha_ros.core.qft.spec import load_spec
    spec = load_spec(os.path.join(ROOT, 'config', 'qft_spec.yaml'))
    assert SB.N_PLANTS == np.prod([spec[f'family.{n}_n'] for n in ('C_eq', 'D_p', 'beta', 'k_T',
                                                                   'k_E')])
    s = 'plant.sensors.'
    loud = SB.from_params({**params, s + 'position_sigma': 2 * params[s + 'position_sigma'],
                           s + 'position_gm_sigma': 2 * params[s + 'position_gm_sigma']})
    assert (loud.offset_bound, loud.band, loud.jump_step) == pytest.approx(
        (2 * b.offset_bound, 2 * b.band, 2 * b.jump_step), rel=1e-12)
    est = Estimator({**params, s + 'position_gm_sigma': 2 * params[s + 'position_gm_sigma']})
    assert est.kf.offset_bound == pytest.approx(2 * b.offset_bound, rel=1e-12)
    assert est.monitor_k[adapt.MK_BAND] > b.band


def test_drifting_states_walk_their_family_sigma_in_the_drift_time(params):
    """q of a drifting adaptive state is p0 Ts / drift_time (its family sigma in drift_time),
    the displacement's and friction's 0; the filter's Q carries it."""
    from eha_ros.core.estimator.params import DRIFTING, TUNED, drift_q
    m, ts = 'estimator.model.', params['plant.sim.Ts']
    for name in ('leakage', 'external_leakage', 'compliance', 'displacement', 'friction'):
        want = TUNED[f'model.p0_{name}'] * ts / params[m + 'drift_time'] \
            if name in DRIFTING else 0
        assert drift_q(params, name) == want, name
    kf = Estimator({**params, m + 'drift_time': 1e3}).kf
    assert kf.Q[kf.i_compliance, kf.i_compliance] == pytest.approx(
        TUNED['model.p0_compliance'] * ts / 1e3, rel=1e-12)


# ------------------------------------------------------------------ why the friction model
def riccati_ratio(params, c_eq: float, q_force: float) -> float:
    """Best RMSE ratio of any linear filter on the leaky chamber model with the plant's TRUE
    parameters: steady-state posterior sigma of x over the raw sensor's sigma (white + Gauss-
    Markov). States x, xdot, p_A, p_B (B on its check valve), the sensor offset b and the
    piston force F_d as a random walk of q_force N^2 per tick; measurements x + b, p_A, p_B;
    the speed noise enters through the pump flow."""
    import dataclasses
    import math
    from scipy.linalg import expm, solve_discrete_are
    from eha_ros.core.estimator.model_kf import zoh
    from eha_ros.core.estimator.estimator import circuit
    from eha_ros.core.plant.parameters import PlantParams
    pp = PlantParams.from_dict(params)
    c = circuit(pp)
    c = dataclasses.replace(c, C_x=c.C_x * c_eq, C_r=c.C_r * c_eq)
    A, B = continuous(c, False, True, params['plant.sensors.position_gm_corner'])
    n = 6
    Ac = np.zeros((n, n))
    Ac[:5, :5], Ac[:5, 5] = A, B[:, 1]
    Bw = np.zeros((n, 1))
    Bw[:5, 0] = B[:, 0]
    Ts = pp.Ts
    F, G = expm(Ac * Ts), zoh(Ac, Bw, Ts)[1]
    s = 'plant.sensors.'
    a = math.exp(-2 * math.pi * params[s + 'position_gm_corner'] * Ts)
    Q = G @ G.T * params[s + 'speed_sigma'] ** 2
    Q[4, 4] += params[s + 'position_gm_sigma'] ** 2 * (1 - a * a)
    Q[5, 5] += q_force
    Q[2, 2] += 1.0
    Q[3, 3] += 1.0
    H = np.zeros((3, n))
    H[0, 0] = H[0, 4] = H[1, 2] = H[2, 3] = 1.0
    R = np.diag([params[s + 'position_sigma'] ** 2] + [params[s + 'pressure_sigma'] ** 2] * 2)
    P = solve_discrete_are(F.T, H.T, Q, R)
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    post = P - K @ H @ P
    raw = math.hypot(params[s + 'position_sigma'], params[s + 'position_gm_sigma'])
    return math.sqrt(post[0, 0]) / raw


def test_force_model_bounds_the_sine_ratio_on_leaky_plants(params):
    """Why the chamber filter models the piston friction (adapt.friction_input) instead of
    eq. 4.36 plus a fast force random walk: on a C_eq x10 plant every newton of unmodelled
    force is 5.7 um/s of modelled velocity, and even with the plant's TRUE parameters no
    linear filter gets the 1 Hz sine RMSE ratio under issue 15's 0.5 while the force walks at
    the old 100 N^2 per tick; with the force modelled (the walk 1e-4 N^2) it can."""
    fast = riccati_ratio(params, 10.0, 100.0)
    slow = riccati_ratio(params, 10.0, 1e-4)
    nominal = riccati_ratio(params, 1.0, 100.0)
    print(f'\nRiccati bound of the RMSE ratio: C_eq x10 {fast:.3f} (100 N^2/tick), '
          f'{slow:.3f} (1e-4 N^2/tick); nominal {nominal:.3f}')
    assert fast > 0.55 and slow < 0.42 and nominal < 0.25
