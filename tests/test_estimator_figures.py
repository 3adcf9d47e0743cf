"""The issue's measured figures on the simulated bench, in batch (core.sim.pid_loop):
nonlinear plant with its default sensor noise + estimator + the Table 3.8 position PID closing
the loop on the ESTIMATE (as the controller does on the bench; the estimate's errors then show
up in the piston motion, which is what the truth comparison is about)."""

import numpy as np
import pytest

from eha_ros.core.sim import pid_loop as batch
from eha_ros.core.estimator import adapt
from eha_ros.core.estimator import fault_detector as fd



def rms(a):
    return float(np.sqrt(np.mean(np.square(a))))


SEEDS = (1, 2, 3, 4)


@pytest.fixture(scope='module')
def sine_1hz(params):
    """30 s of a 1 Hz, 5 mm sine per seed; statistics over 6-30 s (filter and loop settled).
    Several seeds and 24 s each: the sensor's 1 Hz Gauss-Markov wander averages out only
    over seconds, so one short run says little (12 s windows range 0.13-0.39 for the same
    filter)."""
    out = []
    for seed in SEEDS:
        run = batch.estimator_loop(params, batch.sine(5e-3, 1.0), 30.0, seed=seed)
        s = run.t >= 6.0
        est, raw = rms(run.estimate[s] - run.truth[s]), rms(run.measured[s] - run.truth[s])
        print(f'\n1 Hz 5 mm sine, seed {seed}: estimate RMSE {est * 1e6:.2f} um, raw sensor RMSE '
              f'{raw * 1e6:.2f} um, ratio {est / raw:.3f} (goal <= 0.25)')
        out.append((est, raw))
    return out


def test_rmse_quarter_of_raw_sensor_during_1hz_5mm_sine(sine_1hz):
    """Chamber-pressure filter (the default, chamber_kf): every seed meets the goal."""
    for est, raw in sine_1hz:
        assert est <= 0.25 * raw


def test_eq4_35_filter_rmse_during_1hz_5mm_sine(params):
    """The eq. 4.35 filter (estimator.model.structure eq4_35) on the same test: its lumped p_D
    row misses the boost circuit (one chamber compresses, C_r times the cracking pressure),
    a 1 Hz model error it cannot tell from the sensor's Gauss-Markov wander. Regression guard
    of what it achieves (about 0.35), and the reason the chamber filter is the default."""
    p = dict(params)
    p['estimator.model.structure'] = 'eq4_35'
    run = batch.estimator_loop(p, batch.sine(5e-3, 1.0), 12.0, seed=1)
    s = run.t >= 4.0
    est, raw = rms(run.estimate[s] - run.truth[s]), rms(run.measured[s] - run.truth[s])
    print(f'\neq. 4.35 filter: ratio {est / raw:.3f}')
    assert 0.25 * raw < est <= 0.45 * raw


def test_phase_of_estimate_at_7hz_within_10_degrees(params):
    run = batch.estimator_loop(params, batch.sine(1e-3, 7.0), 3.0, seed=2)
    s = run.t >= 1.0 - 1e-9                     # 14 whole periods
    ph = batch.phase_deg(run.estimate[s], run.truth[s], 7.0, run.t[s])
    e = np.exp(-2j * np.pi * 7.0 * run.t[s])
    gain = abs(np.sum(run.estimate[s] * e) / np.sum(run.truth[s] * e))
    est, raw = rms(run.estimate[s] - run.truth[s]), rms(run.measured[s] - run.truth[s])
    print(f'\n7 Hz: phase {ph:.2f} deg, gain {gain:.4f}, RMSE {est * 1e6:.1f} um '
          f'(raw {raw * 1e6:.1f} um)')
    assert abs(ph) <= 10.0
    assert abs(gain - 1.0) < 0.05
    assert est < 0.5 * raw


def test_10um_steps_resolved_without_steady_state_error(params):
    """Thesis Fig. 4.45: a staircase of 10 um steps every 0.5 s, loop closed on the estimate.
    Steady state = the last 0.25 s of each plateau. The estimate settles on every step within
    2 um, the piston moves on every step, and on average by 10 um within 2 um.
    The staircase starts after 2 s at rest: the adaptive leakage correction (adapt.py) converges
    in the first 1-2 s after start (first plateau 2.2 um with a start at 1 s)."""
    hold, n, t0 = 0.5, 11, 2.0
    ref = lambda t: 10e-6 * np.floor(np.maximum(t - t0, 0.0) / hold + (t >= t0))  # noqa: E731
    run = batch.estimator_loop(params, ref, t0 + n * hold + hold, seed=1)
    est_err, truth_lvl = [], []
    for i in range(n + 1):
        t_end = t0 + i * hold
        b = (run.t >= t_end - 0.25) & (run.t < t_end)
        est_err.append(np.mean(run.estimate[b] - run.reference[b]))
        truth_lvl.append(np.mean(run.truth[b]))
    est_err = np.array(est_err[1:])
    steps = np.diff(truth_lvl)
    truth_err = np.array(truth_lvl[1:]) - 10e-6 * np.arange(n)
    print(f'\nestimate steady-state error um: {np.round(est_err * 1e6, 2)}'
          f'\npiston steps um: {np.round(steps * 1e6, 1)} (mean {steps.mean() * 1e6:.2f})'
          f'\npiston vs reference um: {np.round((truth_err - truth_err[0]) * 1e6, 1)}')
    assert np.all(np.abs(est_err) <= 2e-6)
    assert np.all(steps > 0)
    assert abs(steps.mean() - 10e-6) <= 2e-6


@pytest.mark.parametrize('magnitude', [1e-3, -1e-3])
def test_1mm_sensor_jump_detected_within_50ms(params, magnitude):
    run = batch.estimator_loop(params, batch.sine(5e-3, 1.0), 3.0, seed=3,
                            faults=[(2.0, 'msp_bias', magnitude)])
    before = run.fault[run.t < 2.0]
    hit = np.nonzero((run.t >= 2.0) & (run.fault == fd.JUMP))[0]
    assert not before.any()
    assert hit.size, 'jump never detected'
    delay = run.t[hit[0]] - 2.0
    print(f'\n{magnitude * 1e3:+.0f} mm jump detected after {delay * 1e3:.0f} ms')
    assert delay <= 0.050


def test_no_false_alarm_in_60s_of_nominal_noise(params):
    """60 s of closed-loop operation (1 Hz, 5 mm sine) with the default sensor noise."""
    run = batch.estimator_loop(params, batch.sine(5e-3, 1.0), 60.0, seed=7)
    codes, counts = np.unique(run.fault, return_counts=True)
    print(f'\n60 s nominal: fault codes {dict(zip(codes.tolist(), counts.tolist()))}, '
          f'max NIS {run.nis.max():.1f}')
    assert not run.fault.any()


def test_stuck_and_drift_classified(params):
    run = batch.estimator_loop(params, batch.sine(5e-3, 1.0), 2.5, seed=3,
                            faults=[(2.0, 'msp_stuck', 0.0)])
    after = run.fault[run.t >= 2.0]
    first = np.nonzero(after)[0]
    assert first.size and after[first[0]] == fd.STUCK, after[first[0]:first[0] + 5]
    assert run.t[run.t >= 2.0][first[0]] - 2.0 <= 0.050
    run = batch.estimator_loop(params, lambda t: 0.0 * t, 3.5, seed=3,
                            faults=[(2.0, 'msp_drift', 1e-3)])   # 1 mm/s
    # a slow sensor drift while holding (no flow the adapted model could explain) is reported
    # as a drift by the CUSUM or, once the estimate follows the sensor beyond its error band
    # (issue 15: the sensor is the absolute reference), as filter/sensor disagreement
    seen = (run.fault == fd.DRIFT) | (run.consistency == adapt.DISAGREE)
    after = seen[run.t >= 2.0]
    first = np.nonzero(after)[0]
    assert not run.fault[run.t < 2.0].any() and not run.consistency[run.t < 2.0].any()
    assert first.size
    print(f'\n1 mm/s drift reported after {run.t[run.t >= 2.0][first[0]] - 2.0:.3f} s')
    assert run.t[run.t >= 2.0][first[0]] - 2.0 <= 1.0
