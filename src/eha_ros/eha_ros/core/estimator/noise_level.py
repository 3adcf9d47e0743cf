"""Online noise level of the position and pressure sensors, scaling the filter's R (issue 15).

Why: a real sensor's noise is not its datasheet's (cabling, supply, EMI). With the pressure
sensors noisier than R says, their innovations, normalised by that R, pass the load-step test
of the force state (adapt.maneuver, 5 sigma) on noise alone, and every such sample lets the
force state jump; on a leaky plant each newton of it is 5.7 um/s of modelled velocity. On the
random family (every sensor noise x1..2) the 1 Hz sine RMSE ratio reached 1.41, 39 of 200
plants above 0.5; with R matched to the true noise 1 of 200, and keeping the load-step test in
datasheet units (5 x 0.316 bar) while R is measured brought it back to 43 (so that test is
what the noise broke). Tuning R at the worst noise instead costs the nominal figures.

What is measured: the second difference of a sensor's own readings,
``d_k = z_k - 2 z_{k-1} + z_{k-2}``, which removes the signal (the piston's 6 m/s^2 reference
acceleration limit gives 6 um against the white noise's 24 um sigma of d; a pressure transient
lasts a few samples) and keeps the white noise: for white noise sigma_w, a first-order
Gauss-Markov part (sigma_g, pole a per tick) and a quantisation step q,

    E[d^2] = 6 sigma_w^2 + 2 (1 - a)(3 - a) sigma_g^2 + q^2 / 2

(the Gauss-Markov autocovariance sigma_g^2 a^|h| in 6 g0 - 8 g1 + 2 g2). Its mean square is
tracked by a recursive Huber-clipped mean (Huber 1981, sec. 1.2: a sample is limited to
``clip`` times the current RMS, the clipped mean divided by its Gaussian value
E[min(X^2, c^2)], so a load step's pressure transient or a sensor jump does not count as
noise), with growing memory up to ``time`` seconds (weight max(1/(N0 + n), Ts/time), N0
samples of the nominal prior). The level s = sqrt(mean d^2 / E_nominal[d^2]), clipped to
``range``, scales the sensor's whole model: R = s^2 R_nominal, and for the position also the
Gauss-Markov state's process noise (the noise's spectrum is the sensor's, its level the
installation's). The level is measured on the samples the filter uses; a gap (a rejected or
isolated sample) restarts the difference.

Only while the actuator is quiet: with the pump-flow velocity D_p |omega| / A_p above
``quiet_velocity`` the loop on the nonlinear plant carries a motion the filter does not follow
at the sampling rate (a 3 Hz 3 mm sine at up to 57 mm/s: second differences of the noise-free
position 21-34 um RMS, 45 % of the samples above 5 um, of the pressures 190 kPa; the 1 Hz
5 mm sine at up to 31 mm/s: 0.7 um), which would be measured as noise.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

# constants (array nk)
NK_ALPHA, NK_N0, NK_CLIP, NK_KAPPA, NK_LO, NK_HI = 0, 1, 2, 3, 4, 5
NK_DX, NK_DP = 6, 7            # nominal E[d^2] of the position, of one pressure sensor
NK_RX, NK_RP, NK_QGM, NK_IGM = 8, 9, 10, 11   # nominal R entries, Gauss-Markov q, its index
NK_WQ = 12                     # [rad/s] motor speed below which the actuator is quiet
NNK = 13
# state (array ns)
# (samples in a row, differences taken, previous two samples, mean square of d, level)
NS_NX, NS_MX, NS_X1, NS_X2, NS_VX, NS_SX = 0, 1, 2, 3, 4, 5
NS_NP, NS_MP, NS_A1, NS_A2, NS_B1, NS_B2, NS_VP, NS_SP = 6, 7, 8, 9, 10, 11, 12, 13
NNS = 14

N0 = 100.0          # samples of weight the nominal prior carries
CLIP = 3.0          # Huber limit, in RMS of d
MEMORY = 5.0        # [s] memory of the level (a knob until issue 44: 2.5 and 10 s changed no
#                     campaign figure, random:50 seed 1)


def clipped_gain(c: float) -> float:
    """E[min(X^2, c^2)] for X standard normal."""
    phi = math.exp(-0.5 * c * c) / math.sqrt(2.0 * math.pi)
    tail = 0.5 * math.erfc(c / math.sqrt(2.0))
    return 1.0 - 2.0 * tail - 2.0 * c * phi + 2.0 * c * c * tail


def second_difference_power(sigma_w: float, sigma_g: float, a: float, q: float) -> float:
    """E[d^2] of the module docstring."""
    return 6.0 * sigma_w ** 2 + 2.0 * (1.0 - a) * (3.0 - a) * sigma_g ** 2 + 0.5 * q * q


def constants(Ts: float, time: float, lo: float, hi: float, d_x: float, d_p: float,
              R_x: float, R_p: float, q_gm: float, i_gm: int, w_quiet: float) -> np.ndarray:
    nk = np.zeros(NNK)
    nk[NK_WQ] = w_quiet
    nk[NK_ALPHA], nk[NK_N0] = Ts / time, N0
    nk[NK_CLIP], nk[NK_KAPPA] = CLIP, clipped_gain(CLIP)
    nk[NK_LO], nk[NK_HI] = lo, hi
    nk[NK_DX], nk[NK_DP] = d_x, d_p
    nk[NK_RX], nk[NK_RP], nk[NK_QGM], nk[NK_IGM] = R_x, R_p, q_gm, i_gm
    return nk


def reset(nk, ns, R, R1, Q) -> None:
    """Back to the nominal level (R, R1, Q as built)."""
    ns[:] = 0.0
    ns[NS_VX], ns[NS_VP] = nk[NK_DX], nk[NK_DP]
    ns[NS_SX] = ns[NS_SP] = 1.0
    apply(nk, ns, R, R1, Q)


@njit(cache=True)
def apply(nk, ns, R, R1, Q) -> None:
    """R = s^2 R_nominal per sensor; the position's Gauss-Markov q likewise."""
    sx, sp = ns[NS_SX] * ns[NS_SX], ns[NS_SP] * ns[NS_SP]
    R[0, 0] = R1[0, 0] = sx * nk[NK_RX]
    i = int(nk[NK_IGM])
    if i >= 0:
        Q[i, i] = sx * nk[NK_QGM]
    for j in range(1, R.shape[0]):
        R[j, j] = sp * nk[NK_RP]


@njit(cache=True)
def _mean_square(nk, v, n, d) -> float:
    """One Huber-clipped, growing-memory step of the mean square v with the sample d."""
    r = min(d * d, nk[NK_CLIP] * nk[NK_CLIP] * v)
    w = max(1.0 / (nk[NK_N0] + n), nk[NK_ALPHA])
    return v + w * (r / nk[NK_KAPPA] - v)


@njit(cache=True)
def _level(nk, v, v0) -> float:
    s = math.sqrt(v / v0)
    return min(max(s, nk[NK_LO]), nk[NK_HI])


@njit(cache=True)
def update(nk, ns, z, pa, pb, has_p, w, R, R1, Q) -> None:
    """One used sample: position z (and pressures pa, pb when has_p) at motor speed w;
    writes the scaled R (position, pressures), R1 (position only) and the Gauss-Markov q
    into Q. Only a quiet sample (|w| below NK_WQ) is measured."""
    quiet = abs(w) < nk[NK_WQ]
    if ns[NS_NX] >= 2.0 and quiet:
        ns[NS_VX] = _mean_square(nk, ns[NS_VX], ns[NS_MX], z - 2.0 * ns[NS_X1] + ns[NS_X2])
        ns[NS_MX] += 1.0
        ns[NS_SX] = _level(nk, ns[NS_VX], nk[NK_DX])
    ns[NS_X2], ns[NS_X1] = ns[NS_X1], z
    ns[NS_NX] += 1.0
    if not has_p:
        ns[NS_NP] = 0.0
        apply(nk, ns, R, R1, Q)
        return
    if ns[NS_NP] >= 2.0 and quiet:
        v = _mean_square(nk, ns[NS_VP], ns[NS_MP], pa - 2.0 * ns[NS_A1] + ns[NS_A2])
        v = _mean_square(nk, v, ns[NS_MP] + 1.0, pb - 2.0 * ns[NS_B1] + ns[NS_B2])
        ns[NS_VP] = v
        ns[NS_MP] += 2.0
        ns[NS_SP] = _level(nk, v, nk[NK_DP])
    ns[NS_A2], ns[NS_A1] = ns[NS_A1], pa
    ns[NS_B2], ns[NS_B1] = ns[NS_B1], pb
    ns[NS_NP] += 1.0
    apply(nk, ns, R, R1, Q)


@njit(cache=True)
def gap(ns) -> None:
    """A sample not used (rejected, isolated): the next differences restart."""
    ns[NS_NX] = 0.0
    ns[NS_NP] = 0.0

