"""Friction input of the model filters, eq. 4.36 made continuous for a sampled filter (the
choices: core.estimator.model_kf's docstring)."""
from __future__ import annotations

from numba import njit


@njit(cache=True)
def friction_estimate(omega, p_D, has_pd, A_p, D_p, F_s, v_eps):
    """Eq. 4.36, F_L = -sign(xdot) min(|p_D A_p|, F_s), made continuous for a sampled filter.

    sign(xdot) is taken from the pump flow, s = sat(D_p omega / (A_p v_eps)) (a hard sign
    switches F_L by 2 F_s within one Ts at every reversal and kicks the stiff p_D state);
    p_D is the measured load pressure (has_pd False without pressure sensors: |F_L| = F_s).
    Where |s| < 1 the friction blends into sticking, holding the pressure force:
    F_L = -s min(|A_p p_D|, F_s) - (1 - |s|) clip(A_p p_D, -F_s, F_s).
    """
    s = D_p * omega / (A_p * v_eps)
    s = 1.0 if s > 1.0 else (-1.0 if s < -1.0 else s)
    if not has_pd:
        return -s * F_s
    force = A_p * p_D
    held = F_s if force > F_s else (-F_s if force < -F_s else force)
    a = abs(force)
    return -s * (F_s if F_s < a else a) - (1.0 - abs(s)) * held
