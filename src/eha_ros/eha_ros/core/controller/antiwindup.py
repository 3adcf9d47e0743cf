"""Observer-form anti-windup for any proper discrete controller (Astrom & Rundqwist 1989,
"Integrator windup and how to avoid it"; the observer class of Kothare et al. 1994, "A unified
framework for the study of anti-windup designs", Automatica 30(12)), with the saturated loop's
stability checked by the discrete circle criterion.

The controller K(z) = C (zI - A)^-1 B + D runs as

    u = C x + D e,   u_s = sat(u),   x+ = A x + B e + L (u_s - u)

Unsaturated (u_s = u) it is exactly K. Saturated, its dynamics are those of A - L C, placed by
L where the designer wants them (here: poles from config/controller.yaml, designed by
scripts/design_qft). Conditional integration and Hanus' conditioning (L = B/D, the poles at
K's zeros) are special cases; both fail for the stiff design: it has no separate integrator
input, and Tustin puts a zero of K at z = -1.

Stability with the clamp: write u_s = u - q, q = dz(u) the dead zone, in the sector [0, 1].
With the plant P(z) (speed reference -> position, loop delays included), e = -P u_s and
M(z) = C (zI - A)^-1 L, the loop seen by the dead zone is u = T q with

    T = (K P - M)/(1 + K P),      1 - T = (1 + M)/(1 + K P) =: H(z).

The actuator the anti-windup sees is the drive, not only the clamp: its current limit makes
the motor accelerate at most k_T I_max / J_eq, so a reference far ahead of the motor speed is
not followed either (a piston held, a motor starting from rest: the clamp alone lets G's state
run ahead of the motor, 8.6 % overshoot after a 2 mm jump). With the measured motor speed
omega_m the effective actuator is u_a = clip(u_s, omega_m -+ r), r = :func:`drive_reach`, and
L (u_a - u) replaces L (u_s - u); within the reach nothing changes.

Discrete circle criterion (sector [0, k]): the loop is absolutely stable if it is stable
unsaturated and Re[1 - k T] = (1 - k) + k Re H > 0 on the unit circle. Re H >= 0 everywhere
gives this for every k < 1, i.e. for any bound on the unclamped output (|u| <= omega_max/(1 - k)).
At z = 1 the plant's integrator makes H = 0 (H = c_L a_P / a_cl: observer, plant and closed-loop
characteristic polynomials), so k = 1 itself is the limit, not a case.
"""
from __future__ import annotations

import numpy as np
from scipy import signal


def observer_gain(Ad, Cd, poles_s, Ts: float) -> np.ndarray:
    """L placing eig(Ad - L Cd) at exp(s_i Ts) for the continuous poles s_i (rad/s; complex
    ones in conjugate pairs, all distinct, one per controller state)."""
    Ad = np.asarray(Ad, float)
    poles_s = np.asarray(poles_s, complex)
    if poles_s.shape != (Ad.shape[0],):
        raise ValueError(f'anti-windup: {poles_s.size} poles for a controller of order '
                         f'{Ad.shape[0]}')
    if np.any(poles_s.real >= 0):
        raise ValueError('anti-windup poles must be in the left half plane')
    return signal.place_poles(Ad.T, np.asarray(Cd, float).reshape(1, -1).T,
                              np.exp(poles_s * Ts)).gain_matrix.T[:, 0].copy()


def resolvent_rows(Ad, Cd, z) -> np.ndarray:
    """C (zI - A)^-1 for each z, shape (len(z), n)."""
    n = Ad.shape[0]
    I = np.eye(n)
    return np.array([np.linalg.solve((zi * I - Ad).T, np.asarray(Cd, float).ravel()) for zi in z])


def circle_h(Ad, Bd, Cd, Dd, L, P, z) -> np.ndarray:
    """H = (1 + M)/(1 + K P) on the points z (complex), for plants P (N, len(z))."""
    R = resolvent_rows(Ad, Cd, z)
    K = R @ np.asarray(Bd, float).ravel() + float(np.asarray(Dd).ravel()[0])
    M = R @ np.asarray(L, float)
    return (1.0 + M)[None, :] / (1.0 + K[None, :] * P)


def current_accel(k_T: float, I_max: float, J_eq: float) -> float:
    """The motor's acceleration (rad/s^2) at the drive's current limit with no load torque:
    k_T I_max / J_eq (eq. 3.13 with i = I_max)."""
    return k_T * I_max / J_eq


def drive_reach(k_T: float, I_max: float, J_eq: float, Kp_w: float, delay: float) -> float:
    """How far (rad/s) a speed reference can lead the measured motor speed and still be
    followed: the speed-loop error that puts the drive at its current limit,
    k_T I_max / Kp_w (the P part of eq. 4.71), plus what the motor gains at the current-limited
    acceleration (:func:`current_accel`) over ``delay`` (measurement to application: Ts and the
    drive's delay)."""
    return k_T * I_max / Kp_w + current_accel(k_T, I_max, J_eq) * delay


def poles_from_params(real, imag) -> np.ndarray:
    """Complex poles from the YAML's two lists (conjugates listed both)."""
    real, imag = np.asarray(real, float), np.asarray(imag, float)
    if real.shape != imag.shape:
        raise ValueError('antiwindup.poles_real and antiwindup.poles_imag differ in length')
    p = real + 1j * imag
    if not np.allclose(np.sort_complex(p), np.sort_complex(p.conj())):
        raise ValueError('anti-windup poles: complex ones must come in conjugate pairs')
    return p
