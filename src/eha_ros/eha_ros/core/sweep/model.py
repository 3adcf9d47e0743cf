"""Linear-model prediction of the closed position loop, for the Bode overlay of a sweep report.

T(jw) = F G P e^{-jw T_d} / (1 + G P e^{-jw T_d}), P = x/omega_ref of eq. 3.41 with the drive's
velocity loop (incl. its low-pass), T_d = 1.5 Ts + drive delay (command applied at the next
tick, drive FIFO, zero-order hold)."""
from __future__ import annotations

import numpy as np
from scipy import signal

from ..plant import linear


def closed_loop(plant_params: dict, G, F, freqs_hz) -> tuple[np.ndarray, np.ndarray]:
    """(gain_db, phase_deg) of x/x_ref at freqs_hz; G, F as (num, den)."""
    w = 2 * np.pi * np.asarray(freqs_hz, float)
    Ts = plant_params['plant.sim.Ts']
    T_d = 1.5 * Ts + plant_params['plant.drive.delay']
    P = linear.freqresp(linear.velocity_abcd(plant_params, lowpass=True), w)
    Gj = signal.freqresp(signal.lti(*G), w)[1]
    Fj = signal.freqresp(signal.lti(*F), w)[1]
    L = Gj * P * np.exp(-1j * w * T_d)
    T = Fj * L / (1 + L)
    return 20 * np.log10(np.abs(T)), np.degrees(np.unwrap(np.angle(T)))
