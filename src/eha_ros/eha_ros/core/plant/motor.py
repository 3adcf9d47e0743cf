"""PMSM motor electrics: DC equivalent eq. 3.13-3.14 (default) or d-q model eq. 3.10-3.12."""
from numba import njit

from . import layout as L


@njit(cache=True, error_model='numpy')
def current_dc(i, V, w, R, k_E, decay):
    """Exact solution of L di/dt = V - R i - k_E w (eq. 3.14) over h with V, w held;
    decay = exp(-R h / L)."""
    i_ss = (V - k_E * w) / R
    return i_ss + (i - i_ss) * decay


@njit(cache=True, error_model='numpy')
def current_dq(i_d, i_q, V_d, V_q, w, R, L_d, L_q, n_p, lam, h):
    """Implicit Euler of eq. 3.10-3.11 (2x2, speed held): returns (i_d, i_q)."""
    we = n_p * w
    a11 = L_d / h + R
    a12 = -we * L_q
    a21 = we * L_d
    a22 = L_q / h + R
    r1 = V_d + L_d / h * i_d
    r2 = V_q - we * lam + L_q / h * i_q
    det = a11 * a22 - a12 * a21
    return (r1 * a22 - a12 * r2) / det, (a11 * r2 - a21 * r1) / det


@njit(cache=True, error_model='numpy')
def torque_dq(i_d, i_q, n_p, lam, L_d, L_q):
    """Electromagnetic torque eq. 3.12."""
    return 1.5 * n_p * (lam * i_q + (L_d - L_q) * i_d * i_q)


@njit(cache=True, error_model='numpy')
def update(S, b, P, h):
    """Advance one channel's motor currents over h; return the motor torque (eq. 3.12/3.13)."""
    w = S[b + L.C_W]
    if P[L.P_DQ] > 0.5:
        i_d, i_q = current_dq(S[b + L.C_ID], S[b + L.C_I], S[b + L.C_VD], S[b + L.C_VQ], w,
                              P[L.P_R], P[L.P_LD], P[L.P_LQ], P[L.P_NP], P[L.P_LAMBDA], h)
        S[b + L.C_ID] = i_d
        S[b + L.C_I] = i_q
        return torque_dq(i_d, i_q, P[L.P_NP], P[L.P_LAMBDA], P[L.P_LD], P[L.P_LQ])
    i = current_dc(S[b + L.C_I], S[b + L.C_VQ], w, P[L.P_R], P[L.P_KE], P[L.P_EXP_RL])
    S[b + L.C_I] = i
    return P[L.P_KT] * i
