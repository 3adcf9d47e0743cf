"""Linear EHA models from the plant parameters: eq. 3.24, 3.35, 3.41 (corrected), 4.35 (corrected).

Each ``*_abcd`` function returns numpy (A, B, C, D); :func:`to_ss` wraps them in
python-control StateSpace objects. Frequency responses are evaluated from the state space
(:func:`freqresp`) and transfer functions are given as zeros/poles/gain (:func:`zpk`); no
high-order ss2tf numerators are formed.

The piston and load-pressure rows (eq. 3.22-3.23, with eq. 3.22's leakage 2 beta C_eq/V_d,
which the matrices of eq. 3.24 and 4.35 print as beta C_eq/V_d) and the corrections of eq. 4.35
come from :mod:`.hydromech`. Here too: eq. 3.41 row 6 misprints "/L": d/dt(int i_e) = -i -
(Kp_w/k_T) w + (Ki_w/k_T) int w_e + (Kp_w/k_T) w_ref. Linear constants: b = mu (1120 N s/m),
C_eq = C_p + C_c + C_r/2, b_eq from appendix D.1.
"""
from __future__ import annotations

import numpy as np

from . import hydromech as hm
from .parameters import PlantParams


def _p(params) -> PlantParams:
    return params if isinstance(params, PlantParams) else PlantParams.from_dict(params)


def _mech_hydro_rows(p: PlantParams, A: np.ndarray, B: np.ndarray | None = None, i_w=1,
                     i_x=2, i_v=3, i_p=4, i_load=1):
    """Fill the shaft (w, eq. 3.17), piston (x, xdot) and load pressure (p_D) rows (eq.
    3.22-3.23, :func:`.hydromech.load_pressure` with w a state); with ``B``, its column
    ``i_load`` takes F_L towards -x (eq. 3.23)."""
    A[i_w, i_w] = -p.b_eq / p.J_eq
    A[i_w, i_p] = -p.D_p / p.J_eq
    A3, B3 = hm.load_pressure(hm.hydromech(p))
    rows = [i_x, i_v, i_p]
    A[np.ix_(rows, rows)] = A3
    A[rows, i_w] = B3[:, 0]
    if B is not None:
        B[i_v, i_load] = -B3[1, 1]


def voltage_abcd(params, with_load: bool = False):
    """Eq. 3.24: states [i, w, x, xdot, p_D], input V (and F_L, sec. 4.2.2), output x."""
    p = _p(params)
    A = np.zeros((5, 5))
    A[0, 0] = -p.R / p.L
    A[0, 1] = -p.k_E / p.L
    A[1, 0] = p.k_T / p.J_eq
    B = np.zeros((5, 2 if with_load else 1))
    _mech_hydro_rows(p, A, B if with_load else None)
    B[0, 0] = 1.0 / p.L
    C = np.zeros((1, 5))
    C[0, 2] = 1.0
    return A, B, C, np.zeros((1, B.shape[1]))


def torque_abcd(params):
    """Eq. 3.35: states [i, w, x, xdot, p_D, int i_e], input i_ref, output x (P_i)."""
    p = _p(params)
    A = np.zeros((6, 6))
    A[0, 0] = -(p.R + p.Kp_i) / p.L
    A[0, 1] = -p.k_E / p.L
    A[0, 5] = p.Ki_i / p.L
    A[1, 0] = p.k_T / p.J_eq
    _mech_hydro_rows(p, A)
    A[5, 0] = -1.0
    B = np.zeros((6, 1))
    B[0, 0] = p.Kp_i / p.L
    B[5, 0] = 1.0
    C = np.zeros((1, 6))
    C[0, 2] = 1.0
    return A, B, C, np.zeros((1, 1))


def velocity_abcd(params, lowpass: bool = False):
    """Eq. 3.41 (row 6 corrected): states [i, w, x, xdot, p_D, int i_e, int w_e] (+ i_f with
    ``lowpass``: the 1/(s/K_3 + 1) of eq. 4.71 on the current reference), inputs
    [w_ref, F_L], output x: [P_w, P_d]."""
    p = _p(params)
    n = 8 if lowpass else 7
    A = np.zeros((n, n))
    B = np.zeros((n, 2))
    kpw, kiw = p.Kp_w / p.k_T, p.Ki_w / p.k_T
    A[0, 0] = -(p.R + p.Kp_i) / p.L
    A[0, 1] = -p.k_E / p.L
    A[0, 5] = p.Ki_i / p.L
    A[1, 0] = p.k_T / p.J_eq
    _mech_hydro_rows(p, A, B)
    A[5, 0] = -1.0
    A[6, 1] = -1.0
    B[6, 0] = 1.0
    if lowpass:
        # i_f' = K3 (kpw (w_ref - w) + kiw int w_e - i_f); current PI acts on i_f - i
        k3 = p.lowpass_w
        A[7, 1] = -k3 * kpw
        A[7, 6] = k3 * kiw
        A[7, 7] = -k3
        B[7, 0] = k3 * kpw
        A[0, 7] = p.Kp_i / p.L
        A[5, 7] = 1.0
    else:
        A[0, 1] += -kpw * p.Kp_i / p.L
        A[0, 6] = kiw * p.Kp_i / p.L
        B[0, 0] = kpw * p.Kp_i / p.L
        A[5, 1] = -kpw
        A[5, 6] = kiw
        B[5, 0] = kpw
    C = np.zeros((1, n))
    C[0, 2] = 1.0
    return A, B, C, np.zeros((1, 2))


def velocity_loop_abcd(params, lowpass: bool = False):
    """Closed velocity loop w/w_ref (eq. 4.72) from eq. 3.41: same A, output w, input w_ref."""
    A, B, _, _ = velocity_abcd(params, lowpass)
    C = np.zeros((1, A.shape[0]))
    C[0, 1] = 1.0
    return A, B[:, :1], C, np.zeros((1, 1))


def hydromech_abcd(params):
    """Eq. 4.35 (corrected, :func:`.hydromech.load_pressure` with eq. 3.22's leakage): states
    [x, xdot, p_D], inputs [w, F_L] with F_L along +x (as the friction estimate of eq. 4.36),
    output x."""
    A, B = hm.load_pressure(hm.hydromech(_p(params)))
    C = np.array([[1.0, 0.0, 0.0]])
    return A, B, C, np.zeros((1, 2))


def to_ss(abcd):
    """python-control StateSpace from an (A, B, C, D) tuple."""
    import control
    return control.ss(*abcd)


def voltage_ss(params, with_load=False):
    return to_ss(voltage_abcd(params, with_load))


def torque_ss(params):
    return to_ss(torque_abcd(params))


def velocity_ss(params, lowpass=False):
    return to_ss(velocity_abcd(params, lowpass))


def velocity_loop_ss(params, lowpass=False):
    return to_ss(velocity_loop_abcd(params, lowpass))


def hydromech_ss(params):
    return to_ss(hydromech_abcd(params))


def freqresp(abcd, omega, inp: int = 0, out: int = 0) -> np.ndarray:
    """Complex frequency response C (jwI - A)^-1 B + D at angular frequencies omega (rad/s)."""
    A, B, C, D = abcd
    n = A.shape[0]
    omega = np.atleast_1d(np.asarray(omega, float))
    res = np.empty(len(omega), complex)
    for k, w in enumerate(omega):
        x = np.linalg.solve(1j * w * np.eye(n) - A, B[:, inp])
        res[k] = C[out] @ x + D[out, inp]
    return res


def poles(abcd) -> np.ndarray:
    """Eigenvalues of A (the model's poles), sorted by magnitude."""
    ev = np.linalg.eigvals(abcd[0])
    return ev[np.argsort(np.abs(ev))]


def zpk(abcd, inp: int = 0, out: int = 0):
    """(zeros, poles, gain) of one channel: invariant zeros, eigenvalues, gain matched to the
    state-space frequency response at a point away from poles and zeros."""
    import control
    A, B, C, D = abcd
    sys = control.ss(A, B[:, [inp]], C[[out], :], D[[out]][:, [inp]])
    z = np.asarray(control.zeros(sys))
    p = np.linalg.eigvals(A)
    s0 = 1j * 1.2345 * (1.0 + np.max(np.abs(np.concatenate([p, z, [1.0]]))))
    h = freqresp(abcd, [s0.imag], inp, out)[0]
    k = h * np.prod(s0 - p) / np.prod(s0 - z) if len(z) else h * np.prod(s0 - p)
    return z, p, float(np.real(k))


def tf(abcd, inp: int = 0, out: int = 0):
    """python-control TransferFunction built from :func:`zpk` (factored, not ss2tf)."""
    import control
    z, p, k = zpk(abcd, inp, out)
    return control.zpk(z, p, k)
