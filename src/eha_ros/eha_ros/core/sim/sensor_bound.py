"""What the position sensor lets any estimator know of the piston's position (issue 42): the
bound of a steady error.

The sensor reads y = x + g + w (thesis 4.1.2, Fig. 4.6: white noise w, sigma_w, and a
first-order Gauss-Markov error g, sigma_g, corner f_c; core.plant.sensors). Give an estimator
the plant itself: it knows every move x(t) - x(0) exactly, but not where the piston started,
as on a bench (nothing measures the start better than the sensor). What is left to estimate
is the constant x(0) from z = y - (x - x(0)), and the best causal estimate of it is the
Kalman filter on [x0, g] with a diffuse prior::

    x0_k = x0_{k-1},   g_k = a g_{k-1} + sqrt(1 - a^2) sigma_g n_k,   a = exp(-2 pi f_c Ts)
    z_k = x0_k + g_k + w_k

A loop holds its estimate at the reference, so the window mean of this filter's error is how
close to the reference an estimator that knows the plant could hold the piston on that noise
realization: the column ``steady_error_bound_m`` of a step run. Over many runs it is the
floor of the steady error (one run can beat it by chance); a family whose runs' bound exceeds
the limit in some fraction of runs fails at least about that fraction with any estimator.
"""
from __future__ import annotations

import numpy as np

from ..redundancy.health import pole

# the diffuse prior of the start position (m^2): far above any sensor variance
DIFFUSE_VAR = 1.0


def start_gains(n: int, a: float, sigma_w: float, sigma_g: float) -> np.ndarray:
    """Kalman gains (n x 2) of the filter above (a: the Gauss-Markov pole); they do not
    depend on the readings."""
    q = (1.0 - a * a) * sigma_g ** 2
    r = sigma_w ** 2
    # P over [x, g]: x diffuse, g at its stationary variance
    pxx, pxg, pgg = DIFFUSE_VAR, 0.0, sigma_g ** 2
    K = np.empty((n, 2))
    for k in range(n):
        if k:
            # P = F P F' + Q, F = diag(1, a)
            pxg, pgg = a * pxg, a * a * pgg + q
        # S = H P H' + R, H = [1, 1]
        s = pxx + 2.0 * pxg + pgg + r
        kx, kg = (pxx + pxg) / s, (pxg + pgg) / s
        K[k] = kx, kg
        # P = P - K H P
        hx, hg = pxx + pxg, pxg + pgg
        pxx, pxg, pgg = pxx - kx * hx, pxg - kx * hg, pgg - kg * hg
    return K


def start_estimate(y, Ts: float, sigma_w: float, sigma_g: float, f_c: float) -> np.ndarray:
    """The filter's estimate of the constant after each reading of ``y`` (its last axis: the
    readings; leading axes: independent runs)."""
    y = np.asarray(y, float)
    n = y.shape[-1]
    a = pole(f_c, Ts)
    K = start_gains(n, a, sigma_w, sigma_g)
    x = np.zeros(y.shape[:-1])
    g = np.zeros(y.shape[:-1])
    out = np.empty(y.shape)
    for k in range(n):
        g = a * g
        # innovation y - H x_pred, H = [1, 1]
        e = y[..., k] - x - g
        x, g = x + K[k, 0] * e, g + K[k, 1] * e
        out[..., k] = x
    return out


def steady_error_bound(t, measured, truth, window, Ts: float, sigma_w: float,
                       sigma_g: float, f_c: float) -> float:
    """|window mean of the error of the filter above| (m) on one run: the steady error an
    estimator that knows the plant (every move, not the start) would leave. ``window``
    ([t0, t1], the time of ``t``); every reading from the run's start is used."""
    t = np.asarray(t)
    x = np.asarray(truth, float)
    # z - x0: the sensor's error on this run (the filter's error is its estimate of x0 - x0)
    err = start_estimate(np.asarray(measured, float) - x, Ts, sigma_w, sigma_g, f_c)
    win = (t >= window[0] - 1e-9) & (t <= window[1] + 1e-9)
    return float(abs(np.mean(err[win])))
