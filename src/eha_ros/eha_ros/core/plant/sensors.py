"""Sensors (thesis 4.1.2, Fig. 4.6): magnetostrictive position (white + Gauss-Markov + LSB),
motor encoder speed, motor current and chamber pressures (0.316 bar white noise)."""
import math

import numpy as np
from numba import njit

from . import layout as L

BLOCK = 1024        # ticks of noise drawn at once


@njit(cache=True, error_model='numpy')
def sample(S, P, U, n, out):
    """One tick of measurements from the state S and normal draws n (layout.NNOISE).

    Position: x + white + first-order Gauss-Markov (pole exp(-2 pi f_c Ts), state S_GM) +
    fault bias/noise, quantised to the resolution; a stuck sensor keeps its previous output.
    Speeds and currents: white noise. Pressures: white noise + fault bias, or frozen (stuck),
    each sensor on its own.
    """
    on = P[L.P_NOISE_ON]
    a = P[L.P_GM_A]
    gm = a * S[L.S_GM] + math.sqrt(1.0 - a * a) * P[L.P_GM_SIGMA] * n[1] * on
    S[L.S_GM] = gm
    if U[L.U_FX_STUCK] < 0.5:
        x = (S[L.S_X] + on * P[L.P_X_SIGMA] * n[0] + gm + U[L.U_FX_SIGMA] * n[8]
             + U[L.U_FX_BIAS])
        res = P[L.P_X_RES]
        if res > 0.0:
            x = round(x / res) * res
        out[L.M_X] = x
    for c in range(2):
        b = L.S_CH + c * L.NCH
        out[L.M_W0 + c] = S[b + L.C_W] + on * P[L.P_W_SIGMA] * n[2 + c]
        out[L.M_I0 + c] = S[b + L.C_I] + on * P[L.P_I_SIGMA] * n[4 + c]
    if U[L.U_FPA_STUCK] < 0.5:
        out[L.M_PA] = S[L.S_PA] + on * P[L.P_PR_SIGMA] * n[6] + U[L.U_FPA_BIAS]
    if U[L.U_FPB_STUCK] < 0.5:
        out[L.M_PB] = S[L.S_PB] + on * P[L.P_PR_SIGMA] * n[7] + U[L.U_FPB_BIAS]


class NoiseSource:
    """Seeded normal draws (numpy Generator) in blocks of BLOCK ticks: reproducible runs.
    ``block`` is one array for the source's life: each new block is drawn into it (the plant's
    kernel record holds it). ``counter``: a one-element array that holds the rows used (the
    plant's aux vector, which the compiled step advances); its own when not given."""

    def __init__(self, seed: int, counter=None):
        self.seed = seed
        self.block = np.empty((BLOCK, L.NNOISE))
        self._k = counter if counter is not None else np.zeros(1)
        self.restart()

    def restart(self) -> None:
        """Back to the seed's first block."""
        self.rng = np.random.default_rng(self.seed)
        self._draw()

    def _draw(self) -> None:
        self.rng.standard_normal(out=self.block)
        self._k[0] = 0.0

    @property
    def k(self) -> int:
        """Rows of the block already used."""
        return int(self._k[0])

    def refill(self) -> None:
        """A new block when this one is used up (before a tick takes its row)."""
        if self._k[0] >= BLOCK:
            self._draw()

    def next_index(self) -> int:
        """Row of ``self.block`` to use for this tick (draws a new block when used up)."""
        self.refill()
        self._k[0] += 1.0
        return self.k - 1
