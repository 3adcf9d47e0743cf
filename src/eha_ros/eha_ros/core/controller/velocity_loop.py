"""The velocity loop the QFT design assumed against the drive's (eq. 4.71): their mismatch."""
from __future__ import annotations

import numpy as np


def drive_mismatch(p: dict) -> float:
    """Largest relative difference between velocity_controller (the design's G_v, YAML) and
    the drive gains of plant.yaml, G_v = (w_l/k_T)(Kp_w s + Ki_w) / (s^2 + w_l s) (eq. 4.71);
    inf when G_v is not of that order."""
    k_t, kp, ki, wl = (p['plant.motor.k_T'], p['plant.drive.Kp_w'], p['plant.drive.Ki_w'],
                       p['plant.drive.lowpass_w'])
    num = np.array(p['velocity_controller.num'], float)
    den = np.array(p['velocity_controller.den'], float)
    num, den = num / den[0], den / den[0]
    want_num, want_den = np.array([wl * kp / k_t, wl * ki / k_t]), np.array([1.0, wl, 0.0])
    if num.shape != want_num.shape or den.shape != want_den.shape:
        return float('inf')
    return float(max(np.max(np.abs(num - want_num) / np.abs(want_num)),
                     abs(den[1] - wl) / wl, abs(den[2])))
