"""Piston friction, Stribeck model of eq. 3.33 with Table 3.7 coefficients."""
import math

from numba import njit

SQRT_2E = math.sqrt(2.0 * math.e)


@njit(cache=True, error_model='numpy')
def friction(v, model, F_c, F_s, v_s, mu):
    """Friction force F_f(v) and its slope dF_f/dv (eq. 3.33).

    model: 0 none, 1 viscous only (mu v, the linear b of eq. 3.23), 2 Stribeck.
    """
    if model == 0:
        return 0.0, 0.0
    force = mu * v
    slope = mu
    if model == 2:
        vst = v_s * math.sqrt(2.0)
        z = v / vst
        g = math.exp(-z * z)
        force += SQRT_2E * (F_s - F_c) * g * z
        slope += SQRT_2E * (F_s - F_c) * g * (1.0 - 2.0 * z * z) / vst
        vc = v_s / 10.0
        th = math.tanh(v / vc)
        force += F_c * th
        slope += F_c * (1.0 - th * th) / vc
    return force, slope
