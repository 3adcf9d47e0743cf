"""Fixed-step integration of the EHA over one tick (eq. 3.10-3.23, 3.32, 3.33; Fig. 3.12).

Scheme, per sub-step h = Ts / substeps (default 62.5 us):

1. Drive (discrete, every drive period, default 62.5 us = 16 kHz, independent of h): velocity
   PI + low-pass (eq. 4.71) and current PI (eq. 3.34) compute a voltage held until the next
   drive sample (ZOH like the real drive). Halving h therefore does not change the drive.
2. Motor current: exact exponential update of the RL circuit (eq. 3.14) with V and omega held
   (d-q option: implicit Euler of eq. 3.10-3.11). The current is electrically fast but only
   couples to the slow shaft through k_E omega, so holding omega over h is accurate.
3. On-off / bypass valve fractions: linear ramps.
4. Hydro-mechanics, unknowns y = [omega_0, omega_1, p_A, p_B, v] (eq. 3.17, 3.20-3.21, 3.32):
   a theta-method, trapezoidal (theta = 0.5, no numerical damping of the lightly damped
   ~4800 rad/s hydraulic pair, second order) on the linear part (inertia, compressibility,
   laminar leakage, pump flow, reaction torque), and backward Euler on the stiff dissipative
   non-linear forces/flows (Stribeck friction with its tanh(v/(v_s/10)) regularisation,
   end stops, check and relief valves), which are L-stable there: no chatter when sticking.
   The shaft speeds enter linearly and are eliminated exactly (omega_c = a_c - b_c p_D),
   leaving a 3x3 system in (p_A, p_B, v) solved by Newton in closed form (v eliminated,
   then 2x2 Cramer); typically 1-2 iterations since only friction, stops and valves are
   non-linear. x follows from the same theta rule. All scalar code: no arrays, no
   allocation in the inner loop (this is what makes >= 100 simulated s per wall s).
5. Accumulator (eq. 3.18): explicit update of its oil volume from the flows at the new
   pressures (its capacitance is ~1e4 times a chamber's, so explicit is exact enough), which
   conserves oil exactly.

Chamber volumes and leakage coefficients (map option) are frozen over a sub-step.
"""
import math

from numba import njit

from ..jit_cache import drop_stale
from . import layout as L
from .accumulator import pressure as acc_pressure
from .chambers import stiffness
from .drive import current_pi, disable, speed_pi
from .friction import friction
from .motor import update as motor_update
from .piston import end_stop
from .pump import leakage
from .sensors import sample
from .valves import check_flow, ramp, relief_flow

drop_stale(__file__)      # tick() inlines kernels of the other plant modules


@njit(cache=True, error_model='numpy')
def shaft(w0, torque, f, pd0, P):
    """Theta-step of eq. 3.17 solved for the new speed: omega = a - b p_D(new).

    J (w - w0)/h = T - b_eq w_bar - f D_p p_D_bar, bars = theta-weighted; f = valve fraction
    (a closed couple feels no reaction torque).
    """
    h = P[L.P_H]
    th = P[L.P_THETA]
    J = P[L.P_J]
    den = 1.0 / h + th * P[L.P_BEQ] / J
    fd = f * P[L.P_DP] / J
    a = (w0 / h - (1.0 - th) * P[L.P_BEQ] * w0 / J + torque / J - fd * (1.0 - th) * pd0) / den
    return a, th * fd / den


@njit(cache=True, error_model='numpy')
def piston_terms(v, v0, x0, P):
    """Friction (eq. 3.33) + end-stop force at the new state: (F_f - F_stop, its d/dv, F_f)."""
    h = P[L.P_H]
    th = P[L.P_THETA]
    x = x0 + h * (th * v + (1.0 - th) * v0)
    ff, dff = friction(v, int(P[L.P_FRIC]), P[L.P_FC], P[L.P_FS], P[L.P_VS], P[L.P_MU])
    fs, dfx, dfv = end_stop(x, v, P[L.P_XSTOP], P[L.P_KSTOP], P[L.P_CSTOP])
    return ff - fs, dff - dfx * h * th - dfv, ff


@njit(cache=True, error_model='numpy')
def chamber_valves(p, p_acc, P):
    """Check inflow minus relief outflow of one chamber and its derivative (backward Euler)."""
    qc, dqc = check_flow(p_acc, p, P[L.P_CHECK_K], P[L.P_CHECK_CRACK], P[L.P_VALVE_BAND])
    qr, dqr = relief_flow(p, p_acc, P[L.P_RELIEF_K], P[L.P_RELIEF_CRACK], P[L.P_VALVE_BAND])
    return qc - qr, dqc - dqr


@njit(cache=True, error_model='numpy')
def hydromech(S, P, fl, t0, t1, f0, f1, cp0, cp1, cr0, cr1):
    """One sub-step of eq. 3.17 (both shafts), 3.20-3.21, 3.32 (scheme: module docstring).

    Signs: positive omega pumps into chamber A; V_A = V_d + A_p x; each couple's flow,
    cross-port leakage C_p, per-port leakage C_r (to p_acc) and reaction torque scale with
    its valve fraction f; C_c and the bypass connect A and B directly.
    """
    h = P[L.P_H]
    th = P[L.P_THETA]
    A_p = P[L.P_AP]
    D_p = P[L.P_DP]
    m = P[L.P_MP]
    x0 = S[L.S_X]
    v0 = S[L.S_V]
    pa0 = S[L.S_PA]
    pb0 = S[L.S_PB]
    pd0 = pa0 - pb0
    p_acc = S[L.S_PACC]
    b0 = L.S_CH
    b1 = L.S_CH + L.NCH
    w00 = S[b0 + L.C_W]
    w10 = S[b1 + L.C_W]
    kA, kB = stiffness(x0, P[L.P_VD], A_p, P[L.P_BETA], P[L.P_XSTOP])
    ext = f0 * cr0 + f1 * cr1
    cross = P[L.P_CC] + P[L.P_BYPASS_K] * S[L.S_FB] + f0 * cp0 + f1 * cp1
    a0, g0 = shaft(w00, t0, f0, pd0, P)
    a1, g1 = shaft(w10, t1, f1, pd0, P)
    # pump flow into A: q0 - g p_D (new)
    q0 = D_p * (f0 * (th * a0 + (1.0 - th) * w00) + f1 * (th * a1 + (1.0 - th) * w10))
    G = D_p * th * (f0 * g0 + f1 * g1) + cross * th
    cA = pa0 / (h * kA) + q0 - cross * (1.0 - th) * pd0 - ext * ((1.0 - th) * pa0 - p_acc) \
        - A_p * (1.0 - th) * v0
    cB = pb0 / (h * kB) - q0 + cross * (1.0 - th) * pd0 - ext * ((1.0 - th) * pb0 - p_acc) \
        + A_p * (1.0 - th) * v0
    cV = m * v0 / h + A_p * (1.0 - th) * pd0 - fl
    # predictor: repeat the last sub-step's increments (the Newton start, not the answer)
    pa = pa0 + S[L.S_DPA]
    pb = pb0 + S[L.S_DPB]
    v = v0 + S[L.S_DV]
    j13 = A_p * th
    ts = P[L.P_THETA_STIFF]
    if ts < 1.0:
        fp0, _, _ = piston_terms(v0, v0, x0, P)
        cV -= (1.0 - ts) * fp0
    ff = 0.0
    tol = P[L.P_NEWTON_TOL]
    err_prev = 0.0
    for _ in range(int(P[L.P_NEWTON_N])):
        S[L.S_NIT] += 1.0
        qa, dqa = chamber_valves(pa, p_acc, P)
        qb, dqb = chamber_valves(pb, p_acc, P)
        fp, dfp, ff = piston_terms(v, v0, x0, P)
        fp *= ts
        dfp *= ts
        rA = pa / (h * kA) - cA + G * (pa - pb) + ext * th * pa + j13 * v - qa
        rB = pb / (h * kB) - cB - G * (pa - pb) + ext * th * pb - j13 * v - qb
        rV = m * v / h - cV - j13 * (pa - pb) + fp
        j11 = 1.0 / (h * kA) + G + ext * th - dqa
        j22 = 1.0 / (h * kB) + G + ext * th - dqb
        j33 = m / h + dfp
        # eliminate dv = (-rV + j13 (dpa - dpb)) / j33, then 2x2 Cramer
        e = j13 * j13 / j33
        m11 = j11 + e
        m12 = -G - e
        m22 = j22 + e
        s1 = -rA + j13 * rV / j33
        s2 = -rB - j13 * rV / j33
        det = m11 * m22 - m12 * m12
        dpa = (s1 * m22 - m12 * s2) / det
        dpb = (m11 * s2 - m12 * s1) / det
        dv = (-rV + j13 * (dpa - dpb)) / j33
        pa += dpa
        pb += dpb
        v += dv
        # stop test of implicit DAE solvers (Hairer & Wanner): with the contraction rate
        # rho = |d_k| / |d_k-1|, the remaining error is about rho / (1 - rho) |d_k|
        err = max(abs(dpa) / 1e7, abs(dpb) / 1e7, abs(dv) / 0.1)
        if err < tol or (err_prev > 0.0 and err < err_prev
                         and err * err / (err_prev - err) < tol):
            break
        err_prev = err
    pd = pa - pb
    S[L.S_DPA] = pa - pa0
    S[L.S_DPB] = pb - pb0
    S[L.S_DV] = v - v0
    S[L.S_X] = x0 + h * (th * v + (1.0 - th) * v0)
    S[L.S_V] = v
    S[L.S_PA] = pa
    S[L.S_PB] = pb
    S[b0 + L.C_W] = a0 - g0 * pd
    S[b1 + L.C_W] = a1 - g1 * pd
    S[L.S_FF] = ff          # at the last Newton iterate (within tolerance of v)


@njit(cache=True, error_model='numpy')
def accumulator_step(S, P, ext):
    """Oil balance of the accumulator circuit (eq. 3.18): port leakage + relief - check flows.

    ext = sum over couples of valve fraction x C_r.
    """
    p_acc = S[L.S_PACC]
    pa = S[L.S_PA]
    pb = S[L.S_PB]
    ra, _ = relief_flow(pa, p_acc, P[L.P_RELIEF_K], P[L.P_RELIEF_CRACK], P[L.P_VALVE_BAND])
    rb, _ = relief_flow(pb, p_acc, P[L.P_RELIEF_K], P[L.P_RELIEF_CRACK], P[L.P_VALVE_BAND])
    qa, _ = check_flow(p_acc, pa, P[L.P_CHECK_K], P[L.P_CHECK_CRACK], P[L.P_VALVE_BAND])
    qb, _ = check_flow(p_acc, pb, P[L.P_CHECK_K], P[L.P_CHECK_CRACK], P[L.P_VALVE_BAND])
    S[L.S_QREL] = ra + rb
    q = ext * (pa + pb - 2.0 * p_acc) + ra + rb - qa - qb
    v_oil = S[L.S_VOIL] + P[L.P_H] * q
    v_oil = min(max(v_oil, 0.0), 0.95 * P[L.P_ACC_V0])
    S[L.S_VOIL] = v_oil
    S[L.S_PACC] = acc_pressure(v_oil, P[L.P_ACC_V0], P[L.P_ACC_P0], P[L.P_PATM])


@njit(cache=True, error_model='numpy')
def channel(S, P, U, c, drive_now, p_d, T):
    """Drive + motor of couple c over one sub-step, valve ramp, pump leakage coefficients.

    Returns (theta-averaged motor torque, valve fraction, C_p, C_r).
    """
    th = P[L.P_THETA]
    b = L.S_CH + c * L.NCH
    t_old = S[b + L.C_TQ]
    if U[L.U_EN0 + c] > 0.5 and U[L.U_FAIL0 + c] < 0.5:
        if drive_now:
            i_ref = speed_pi(S, b, U[L.U_WREF], P)
            current_pi(S, b, i_ref, P)
        t_new = motor_update(S, b, P, P[L.P_H])
    else:
        if S[b + L.C_VQ] != 0.0 or S[b + L.C_I] != 0.0 or S[b + L.C_IW] != 0.0:
            disable(S, b)
        t_new = 0.0
    S[b + L.C_TQ] = t_new
    f = ramp(S[b + L.C_FV], U[L.U_VT0 + c], P[L.P_ONOFF_RATE])
    S[b + L.C_FV] = f
    cp, cr = leakage(P[L.P_CP], P[L.P_CR], P[L.P_LEAK_TABLE] > 0.5, T, S[b + L.C_W], p_d,
                     U[L.U_LEAK0 + c])
    return th * t_new + (1.0 - th) * t_old, f, cp, cr


@njit(cache=True, error_model='numpy')
def substep(S, P, U, k, T):
    """One sub-step: drives, motor currents, valve ramps, hydro-mechanics, accumulator."""
    drive_now = k % int(P[L.P_DRIVE_EVERY]) == 0
    p_d = S[L.S_PA] - S[L.S_PB]
    t0, f0, cp0, cr0 = channel(S, P, U, 0, drive_now, p_d, T)
    t1, f1, cp1, cr1 = channel(S, P, U, 1, drive_now, p_d, T)
    S[L.S_FB] = ramp(S[L.S_FB], U[L.U_BT], P[L.P_BYPASS_RATE])
    hydromech(S, P, U[L.U_FL], t0, t1, f0, f1, cp0, cp1, cr0, cr1)
    accumulator_step(S, P, f0 * cr0 + f1 * cr1)


@njit(cache=True, error_model='numpy')
def tick(S, P, U, T, n_sub, noise, row, meas, backup):
    """Advance S by one tick (n_sub sub-steps, inputs U held) and sample the sensors.

    If the state became non-finite (should not happen for finite inputs) it is restored from
    ``backup`` (scratch of S's size: no allocation per tick) and False is returned.
    """
    backup[:] = S
    for k in range(n_sub):
        substep(S, P, U, k, T)
    ok = True
    for i in range(S.shape[0]):
        if not math.isfinite(S[i]):
            ok = False
    if not ok:
        S[:] = backup
    sample(S, P, U, noise[row], meas)
    return ok
