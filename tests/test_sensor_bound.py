"""The steady error's floor set by the position sensor (core.sim.sensor_bound): the Kalman
filter of a constant in white + Gauss-Markov noise, and the column of a step run."""
import math

import numpy as np
import pytest

from eha_ros.core.sim import campaign as C
from eha_ros.core.sim import family as F
from eha_ros.core.sim import scenarios as SC
from eha_ros.core.sim.sensor_bound import start_estimate, steady_error_bound

TS = 1e-3


def gauss_markov(rng, runs, n, sigma, f_c):
    a = math.exp(-2.0 * math.pi * f_c * TS)
    g = np.empty((runs, n))
    g[:, 0] = sigma * rng.standard_normal(runs)
    for k in range(1, n):
        g[:, k] = a * g[:, k - 1] + math.sqrt(1.0 - a * a) * sigma * rng.standard_normal(runs)
    return g


def test_white_noise_alone_gives_the_running_mean():
    """Without the Gauss-Markov part the best estimate of a constant is the mean of the
    readings so far (the diffuse prior leaves nothing of its own)."""
    rng = np.random.default_rng(3)
    y = 2e-3 + 10e-6 * rng.standard_normal((4, 500))
    xh = start_estimate(y, TS, 10e-6, 0.0, 1.0)
    assert np.max(np.abs(xh - np.cumsum(y, axis=1) / np.arange(1, 501))) < 1e-11


def test_the_filter_beats_the_plain_mean_and_matches_the_sensor_model():
    """Sensor of config/plant.yaml (10 um white, 20 um Gauss-Markov at 1 Hz), 1.6 s of readings,
    the window 1.1-1.6 s: the window mean of the filter's error has a sigma of about 8.5 um
    (1 - 2.5 % of runs beyond 20 um), less than the running mean's, and it grows with the
    noise (x2: about 17 um)."""
    rng = np.random.default_rng(5)
    n, runs = 1601, 3000
    win = slice(1100, 1601)
    sig = {}
    for m in (1.0, 2.0):
        y = m * (gauss_markov(rng, runs, n, 20e-6, 1.0)
                 + 10e-6 * rng.standard_normal((runs, n)))
        e = start_estimate(y, TS, m * 10e-6, m * 20e-6, 1.0)[:, win].mean(axis=1)
        sig[m] = float(np.std(e))
        mean = (np.cumsum(y, axis=1) / np.arange(1, n + 1))[:, win].mean(axis=1)
        assert sig[m] < 0.97 * np.std(mean)
    assert 7.5e-6 < sig[1.0] < 9.5e-6
    assert sig[2.0] == pytest.approx(2.0 * sig[1.0], rel=0.1)
    # noise-free: no error
    assert start_estimate(np.full(50, 1e-3), TS, 1e-9, 1e-9, 1.0)[-1] == pytest.approx(1e-3)


def test_the_bound_ignores_the_move_and_reads_only_the_sensor_error():
    """The bound of a run is the filter on the sensor's error (measured - truth): the same
    for any trajectory of the piston, zero for a perfect sensor."""
    rng = np.random.default_rng(7)
    t = np.arange(1601) * TS
    noise = gauss_markov(rng, 1, 1601, 20e-6, 1.0)[0] + 10e-6 * rng.standard_normal(1601)
    args = ((1.1, 1.6), TS, 10e-6, 20e-6, 1.0)
    still = np.zeros_like(t)
    move = 5e-3 * (1.0 - np.exp(-np.maximum(t - 0.1, 0.0) / 0.03))
    b0 = steady_error_bound(t, still + noise, still, *args)
    assert steady_error_bound(t, move + noise, move, *args) == pytest.approx(b0, rel=1e-9)
    assert steady_error_bound(t, move, move, *args) < 1e-15
    assert 0.0 < b0 < 60e-6


def test_step_runs_report_the_floor_below_the_stacks_error_on_average():
    """The step scenario's column: on 12 nominal runs of their own noise the floor is below
    the stack's steady error in rms (an estimator that knows the plant does at least as well
    as the stack's), and both are a few um, as the sensor model predicts."""
    nom = C.nominal_params()
    one = {c: 1.0 for c in F.COLUMNS}
    scn = SC.load('step')
    err, bound = [], []
    for seed in range(12):
        figs, _ = SC.run(scn, nom, one, C.noise_seed(1, seed), trace=False)
        err.append(figs['steady_error_m'])
        bound.append(figs['steady_error_bound_m'])
    rms = lambda v: float(np.sqrt(np.mean(np.square(v))))    # noqa: E731
    assert 2e-6 < rms(bound) < rms(err) < 15e-6
    assert np.corrcoef(err, bound)[0, 1] > 0.3
