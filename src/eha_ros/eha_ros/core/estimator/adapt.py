"""Adaptive model states, their projection, and the consistency monitor of the position
estimator: written once, compiled, called by the Python filter (chamber_kf, estimator) and by
the compiled stepper (stepper.estimate), so both paths run the same operations.

Adaptive states (issue 15; Simon, "Optimal State Estimation", 2006, sec. 7.4-7.5 parameter
estimation by state augmentation and constrained filtering by estimate projection): the
uncertain flow parameters of Table 4.5 that the pressure sensors cannot see, as relative
corrections held as random-walk states (k_T and k_E need none: the filter takes the measured
motor speed as its input),

- lambda: leakage, every leakage flow of the chamber model (C_x and C_r of eq. 3.15/3.20-3.21)
  times (1 + lambda); Table 4.5 C_eq x0.1..10 is lambda in -0.9..9;
- delta: displacement, the pump flow D_p omega times (1 + delta); Table 4.5 D_p x0.8..1;
- kappa: compliance, the chambers' V_d/beta times (1 + kappa); Table 4.5 beta x0.7..1.4 is
  kappa in -0.29..0.43. Its flow -kappa V_d/beta dp/dt uses the filter's own chamber-pressure
  increment over the previous tick (posterior to posterior): the position error it explains
  is kappa V_d/(beta A_p) times the pressure change (a 10 um step at every load reversal
  with beta x0.7), so the one-tick lag and the pressure noise in it do not accumulate;
- epsilon: external leakage, the per-port flow C_r (p - p_acc) to the accumulator circuit
  times (1 + epsilon), lambda then scaling the cross-port C_x = C_p + C_c only: the two
  paths load the chambers differently (Fig. 3.12: C_r drains the loaded chamber while the
  other sits on its check valve, C_x feeds the other chamber, which then floats above it),
  so one lambda cannot balance both chamber rows when the split differs from nominal;
- phi: piston friction, the Stribeck curve of eq. 3.33 (:func:`friction_input`) times
  (1 + phi); the random family's F_c, F_s x0.5..2 is phi in -0.5..1;
- v_f: unmodelled flow (velocity units), what the states above leave over while holding a
  load (:func:`flow_noise`).

Each enters the chamber rows as a flow multiplying a known input (the prior chamber pressures,
the held speed, the pressure increment), so its F column is the ZOH column of a unit flow into
each chamber times that flow. Without them the stiff pressure rows (beta/V_d = 3.4e12 Pa/m^3:
1e-6 m^3/s of flow error is 3.4 kPa per tick against q_chamber's 0.1 kPa) pin the velocity to
the nominal flow balance, and the position sensor's disagreement goes into the sensor offset
b.

Projection: after each update the adaptive states are clipped to their ranges and the
sensor's Gauss-Markov offset b to +-offset_bound (the sensor's own error band); while filter
and sensor disagree beyond the band, or a parameter sits on its bound, the position's process
noise opens (:func:`disagree_noise`), so the estimate does not stay away from the measurement,
whatever the model says; it opens part way under a varying or swinging load
(:func:`load_variation`, :func:`load_swinging`).
Also here: the EKF predict with the leakage Jacobian, the load-step process noise
(:func:`maneuver`) and the consistency monitor (:func:`monitor`).
"""
from __future__ import annotations

import math

from numba import njit

from ..plant.friction import friction as stribeck
from .kernels import mulv, propagate

# consistency verdicts (Estimator.consistency)
OK, MODEL, DISAGREE, SENSOR = 0, 1, 2, 3      # in rising precedence
VERDICTS = {OK: 'ok', SENSOR: 'sensor_fault', MODEL: 'model_mismatch',
            DISAGREE: 'filter_sensor_disagree'}

EDGE_TICKS = 200        # net updates with a clipped parameter that make an edge

# Constants of the stages that were knobs until issue 44's knob ablation (scripts/ablation
# --vary, random:50, tuning seed 1): x0.5 and x2 changed no passed run and no worst figure
PRESSURE_LOWPASS = 30.0     # [Hz] low-pass of the measured p_D as a model input (friction,
#                             leakage column)
FLOW_REPORT = 2.0e-5        # [m/s] |v_f| reported as model_mismatch above it (flow_noise): the
#                             load-step spec's steady error (20 um) per second
LOAD_VARIANCE_TIME = 2.0    # [s] time constant of the pressure difference's variance about
#                             its mean (load_variation)
LOAD_SWING_BAND = 1.5       # load_swinging's band: x the pressure difference friction holds at
#                             the top of the friction state's range (high-friction plants flip
#                             by about that in a sine without load)
LOAD_SWING_HOLD = 1.0       # [s] load_swinging holds each side this long after the pressure
#                             difference was last beyond the band on it: a 5 kN load at 1 Hz is
#                             beyond it on one side for 38 % of its period, so the hold bridges
#                             the rest (down to about 0.8 Hz) and the crossings of its mean

# piston-friction model constants (array fk) and state (array fs): :func:`friction_input`
FK_AP, FK_DP, FK_CX, FK_CR, FK_PACC, FK_FC, FK_FS, FK_VS, FK_ALPHA, FK_ILAM, FK_IDEL, \
    FK_IPHI, FK_IEPS, FK_VREST, FK_NREST, FK_QREST = range(16)
NFK = 16
FS_V, FS_F, FS_Q, FS_N = 0, 1, 2, 3
NFS = 4

# monitor constants (array mk) and state (array ms)
MK_ALPHA, MK_BAND, MK_N, MK_HOLD = 0, 1, 2, 3
NMK = 4
MS_D, MS_N, MS_HOLD, MS_VERDICT, MS_DET, MS_DMAX = 0, 1, 2, 3, 4, 5
NMS = 6

# flow_noise state (array fl): the run of updates meeting its gate, the pressure difference
# at the run's start, reported (1) or not
FL_N, FL_DP, FL_ACTIVE = 0, 1, 2
NFLOW = 3

# load_variation state (array lv): mean of p_A - p_B, its variance about that mean; and
# load_swinging's hold counters (ticks left) above and below that mean
LV_DPM, LV_DPV, LV_ABOVE, LV_BELOW = 0, 1, 2, 3
NLV = 4


@njit(cache=True)
def unit_flows(i_eps, pa, pb, dpa, dpb, omega, C_x, C_r, p_acc, D_p, c_Ts):
    """The nominal flows the adaptive states scale, into chamber A and into B (m^3/s): lambda's
    (qa, qb: the cross-port flow, and the per-port one too without epsilon), delta's pump flow
    qd (into A, out of B), kappa's compliance flows (ka, kb) and epsilon's per-port flows (ra,
    rb). pa, pb: the prior chamber pressures (Pa), dpa, dpb their increments over the previous
    tick (Pa), omega the held speed (rad/s), c_Ts = V_d/(beta Ts) (m^3/(Pa s))."""
    xa, xb = -C_x * (pa - pb), -C_x * (pb - pa)        # nominal cross-port flow into A, B
    ra, rb = -C_r * (pa - p_acc), -C_r * (pb - p_acc)  # nominal per-port flow into A, B
    qa, qb = (xa, xb) if i_eps >= 0 else (xa + ra, xb + rb)
    return qa, qb, D_p * omega, -c_Ts * dpa, -c_Ts * dpb, ra, rb


@njit(cache=True)
def parameter_columns(F, L, row0, col0, n_lin, i_lam, i_del, i_kap, i_eps, pa, pb, dpa, dpb,
                      omega, C_x, C_r, p_acc, D_p, c_Ts):
    """F columns of lambda, delta, kappa, epsilon (module doc): L[row0 + i, col0] and
    L[row0 + i, col0 + 1] are the ZOH columns of a unit flow (m^3/s) into chamber A and into
    chamber B, times each state's :func:`unit_flows`. With epsilon (i_eps >= 0) lambda carries
    the cross-port flow and epsilon the per-port flow to the accumulator; without, lambda
    carries both."""
    qa, qb, qd, ka, kb, ra, rb = unit_flows(i_eps, pa, pb, dpa, dpb, omega, C_x, C_r, p_acc,
                                            D_p, c_Ts)
    for i in range(n_lin):
        ga = L[row0 + i, col0]
        gb = L[row0 + i, col0 + 1]
        if i_lam >= 0:
            F[i, i_lam] = ga * qa + gb * qb
        if i_del >= 0:
            F[i, i_del] = (ga - gb) * qd
        if i_kap >= 0:
            F[i, i_kap] = ga * ka + gb * kb
        if i_eps >= 0:
            F[i, i_eps] = ga * ra + gb * rb


@njit(cache=True)
def parameter_flows(x, i_lam, i_del, i_kap, i_eps, pa, pb, dpa, dpb, omega, C_x, C_r, p_acc,
                    D_p, c_Ts):
    """The adaptive states' flows into chamber A and into B (m^3/s): each state times its
    :func:`unit_flows` (what :func:`parameter_columns` puts in F, before the ZOH columns)."""
    qa, qb, qd, ka, kb, ra, rb = unit_flows(i_eps, pa, pb, dpa, dpb, omega, C_x, C_r, p_acc,
                                            D_p, c_Ts)
    fa = fb = 0.0
    for i, a, b in ((i_lam, qa, qb), (i_del, qd, -qd), (i_kap, ka, kb), (i_eps, ra, rb)):
        if i >= 0:
            fa += x[i] * a
            fb += x[i] * b
    return fa, fb


@njit(cache=True)
def leak_flow(x, i_lam, i_eps, C_x, C_r, p_acc) -> float:
    """The flow the loaded chamber loses (m^3/s, signed as p_D = p_A - p_B): q_L = (1 + lambda)
    C_x p_D + (1 + epsilon) C_r (p_hi - p_acc) sign(p_D), with the filter's pressures and
    leakage states (lambda for epsilon when epsilon is not a state). The low chamber sits on
    its check valve (Fig. 3.12), so the loaded side loses its whole per-port leakage C_r, not
    C_r/2 as in eq. 3.22's C_eq: what the pump must supply to hold a load."""
    lam = x[i_lam] if i_lam >= 0 else 0.0
    eps = x[i_eps] if i_eps >= 0 else lam
    pd = x[2] - x[3]
    p_hi = x[2] if pd >= 0.0 else x[3]
    return ((1.0 + lam) * C_x * pd
            + (1.0 + eps) * C_r * (p_hi - p_acc) * (1.0 if pd >= 0.0 else -1.0))


@njit(cache=True)
def friction_input(fk, fs, x, omega) -> float:
    """Piston friction of the filter's mechanical row: the plant's Stribeck curve (eq. 3.33,
    Table 3.7, without its viscous part mu v, which is the row's b) at the pump-flow velocity
    v_f = (D_p (1 + delta) omega - q_L) / A_p, the flow balance of the high-pressure chamber
    without its compliance flow, q_L its :func:`leak_flow` (14 mm/s more than eq. 3.22's C_eq
    would say at C_eq x10 under 5 kN), prior states, low-passed (fk[FK_ALPHA] per tick:
    command chatter must not flip it). Returns the nominal force input F_L = -F(v_f); fs[FS_F]
    keeps F(v_f) for the friction-scale column (:func:`friction_column`).

    Why the flow velocity and not the filter's own xdot: the friction is stiff near v = 0
    (F_c / (v_s / 10) = 1.5e5 N s/m against m_p = 2 kg), evaluated at a state it feeds back
    within one tick; the pump flow is an input. Why this model and not eq. 4.36's sign with a
    fast force random walk: with the leakage of C_eq x10 every newton of unmodelled piston
    force is 5.7 um/s of modelled velocity (C F / A_p^2), and the force noise then bounds
    the 1 Hz sine RMSE ratio at 0.61 even with the plant's true parameters (steady-state
    Riccati, tests/test_estimator_robust.py); with this curve and a slow force walk it is
    0.4.

    Rest (stiction, eq. 3.33 at v -> 0): while |v_f| has stayed below fk[FK_VREST] for
    fk[FK_NREST] ticks, the friction input is held at its last value and fs[FS_Q] =
    fk[FK_QREST] is added to the force state's random walk (:func:`maneuver`): at rest the
    friction is whatever holds the piston (anywhere within +-F_s), so the force state carries
    it, and the holding force also absorbs the flow errors of the leakage paths that the
    adaptive states cannot separate at one operating point (slightly conservative there: mean
    NIS 0.96 and 2.81 for 1 and 3 measurements while holding); v_f is then a small difference
    of large, uncertain pump and leakage flows (C_eq x10 under 5 kN: 110 cm^3/s of each), and
    the steep curve near v = 0 (1.7e5 N s/m) would turn their error into tens of newtons of
    modelled friction that the slow force walk cannot absorb (the piston ended 160 um off the
    target). A reversal passes the band in tens of ms and keeps the curve. The filter starts
    at rest (its velocity state 0, ChamberKF.reset: the count full, the force 0): a load that
    rises from the first tick goes to the force state, where counting rest_time first left it
    to the friction scale phi (the stiffness scenario's 5 kN at 1 Hz on the softest corner,
    tuning seeds 1, 3, 5: phi +0.5..+0.9 after 0.3 s, and filter_sensor_disagree at 0.8 s on
    seed 3). phi is still not observable there: once v_f leaves the band (the leakage states
    still learning) it wanders, to -0.7..-0.9 on those seeds."""
    idl = int(fk[FK_IDEL])
    dlt = x[idl] if idl >= 0 else 0.0
    q_l = leak_flow(x, int(fk[FK_ILAM]), int(fk[FK_IEPS]), fk[FK_CX], fk[FK_CR], fk[FK_PACC])
    v = (fk[FK_DP] * (1.0 + dlt) * omega - q_l) / fk[FK_AP]
    fs[FS_V] += fk[FK_ALPHA] * (v - fs[FS_V])
    fs[FS_N] = fs[FS_N] + 1.0 if abs(fs[FS_V]) < fk[FK_VREST] else 0.0
    rest = fs[FS_N] >= fk[FK_NREST]
    if not rest:                                 # at rest the last force is held
        f, _ = stribeck(fs[FS_V], 2, fk[FK_FC], fk[FK_FS], fk[FK_VS], 0.0)
        fs[FS_F] = f
    fs[FS_Q] = fk[FK_QREST] if rest else 0.0
    return -fs[FS_F]


@njit(cache=True)
def friction_column(F, G, n_lin, i_phi, fs) -> None:
    """F column of the friction scale phi (friction x (1 + phi); the family's F_c, F_s
    x0.5..2): each row's :func:`friction_entry`."""
    if i_phi >= 0:
        for i in range(n_lin):
            F[i, i_phi] = friction_entry(G[i, 1], fs)


@njit(cache=True)
def friction_entry(g, fs) -> float:
    """One row of :func:`friction_column`: the row's force input entry g of G times the
    nominal force input -F(v_f)."""
    return -g * fs[FS_F]


@njit(cache=True)
def pressure_increments(pl, pa, pb) -> None:
    """pl = [p_A, p_B at the last predict, their increments since]: the compliance flow's
    input (a low-pass of the increments at 10-30 Hz was measured worse and removed, issue 44);
    then pl[0:2] <- (pa, pb)."""
    pl[2] = pa - pl[0]
    pl[3] = pb - pl[1]
    pl[0] = pa
    pl[1] = pb


@njit(cache=True)
def predict_jacobian(x, P, F, Fj, Dm, row0, col0, col1, n_lin, lam, eps, G, u, Q, tmp):
    """EKF predict of the adaptive chamber model: mean x <- F x + G u (eq. 4.1; the flows of
    lambda, delta, kappa, epsilon in F's parameter columns), covariance P <- Fj P Fj' + Q
    (eq. 4.2) with the Jacobian Fj = F + lam D + eps E, D = Dm[row0:, col0:] and E =
    Dm[row0:, col1:] the ZOH sensitivities of the linear block to lambda's and epsilon's
    leakage paths (Frechet derivative of expm): without it the filter would not know that its
    pressure errors move the piston through the adapted leakage (x10 leakage: 90 % of the
    leakage flow), and would trust its dead reckoning too much on a leaky plant."""
    n = x.shape[0]
    for i in range(n):
        for j in range(n):
            Fj[i, j] = F[i, j]
    for i in range(n_lin):
        for j in range(n_lin):
            Fj[i, j] += lam * Dm[row0 + i, col0 + j] + eps * Dm[row0 + i, col1 + j]
    xn = tmp[0]
    mulv(F, x, xn, None, False)
    mulv(G, u, xn, xn, False)
    x[:] = xn
    propagate(Fj, P, Q, tmp)


@njit(cache=True)
def maneuver(Q, i_load, pz, load_jump_z, q_load, q_load_jump) -> None:
    """Adjustable-level process noise of the external-force state (Bar-Shalom, Li,
    Kirubarajan 2001, sec. 11.2, maneuver detection): after a sample whose pressure
    innovation exceeds ``load_jump_z`` (normalised) the next predict uses q_load_jump, else q_load.
    A load step is a force the random walk of q_load would take seconds to learn; meanwhile the
    oil's compression (0.4 mm for 10 kN) would be taken for sensor offset and parameters."""
    if i_load >= 0:
        Q[i_load, i_load] = q_load_jump if pz > load_jump_z else q_load


@njit(cache=True)
def clip(v, lo, hi):
    return lo if v < lo else (hi if v > hi else v)


@njit(cache=True)
def on_bound(x, i, lo, hi) -> int:
    """Clip x[i] to [lo, hi]; 1 when it was beyond."""
    v = clip(x[i], lo, hi)
    out = 1 if v != x[i] else 0
    x[i] = v
    return out


@njit(cache=True)
def project(x, i_lam, lam_lo, lam_hi, i_del, del_lo, del_hi, i_kap, kap_lo, kap_hi, i_phi,
            phi_lo, phi_hi, i_eps, eps_lo, eps_hi, i_gm, b_max, clipped, edge_ticks) -> int:
    """Estimate projection onto the bounds. ``clipped[0]`` counts up (to 2 edge_ticks) on an
    update that clipped an adaptive state, down on one that did not; returns 1 (edge: the
    model is at the edge of what it may adapt to) while it is at least ``edge_ticks``: a
    parameter held on its bound, not one that touched it in a transient (start-up, p0 the
    whole family)."""
    n = 0
    if i_lam >= 0:
        n += on_bound(x, i_lam, lam_lo, lam_hi)
    if i_del >= 0:
        n += on_bound(x, i_del, del_lo, del_hi)
    if i_kap >= 0:
        n += on_bound(x, i_kap, kap_lo, kap_hi)
    if i_phi >= 0:
        n += on_bound(x, i_phi, phi_lo, phi_hi)
    if i_eps >= 0:
        n += on_bound(x, i_eps, eps_lo, eps_hi)
    if i_gm >= 0 and b_max > 0.0:
        x[i_gm] = clip(x[i_gm], -b_max, b_max)
    if n > 0:
        clipped[0] = clipped[0] + 1 if clipped[0] < 2 * edge_ticks else clipped[0]
    elif clipped[0] > 0:
        clipped[0] -= 1
    return 1 if clipped[0] >= edge_ticks else 0


@njit(cache=True)
def monitor(mk, ms, z, x_hat, sensor_code, drift, edge) -> int:
    """Consistency verdict of one tick (Bar-Shalom, Li, Kirubarajan, "Estimation with
    Applications to Tracking and Navigation", 2001, sec. 5.4 filter consistency, 11.2 fading
    memory / innovation bias): d = z - x_hat, the measurement's disagreement with the
    estimate, low-passed (the white noise averages out, the sensor's Gauss-Markov wander and a
    model error do not).

    - MODEL: a slow persistent innovation bias (the detector's CUSUM), an adaptive state on
      its bound or an unmodelled flow (the callers pass the first and the flow as ``drift``):
      the model is wrong; adaptation absorbs what is within its ranges;
    - DISAGREE: |low-passed d| above the sensor's error band for MK_N samples: the filter
      holds the estimate away from the measurement by more than the sensor can be wrong;
    - SENSOR: the fault detector reports a stuck sensor (frozen readings), or a jump (a fast
      innovation step with quiet pressures) while the disagreement condition holds: the
      disagreement is the sensor's.
    Precedence SENSOR > DISAGREE > MODEL. A verdict stays reported MK_HOLD samples after its
    condition clears (a milder condition meanwhile does not extend it), then the current one.
    DISAGREE and SENSOR are alarms (:func:`alarm`); SENSOR calls for the safe state
    (:func:`safe_state`).
    """
    ms[MS_D] += mk[MK_ALPHA] * ((z - x_hat) - ms[MS_D])
    a = abs(ms[MS_D])
    if a > ms[MS_DMAX]:
        ms[MS_DMAX] = a
    ms[MS_N] = ms[MS_N] + 1 if a > mk[MK_BAND] else 0
    now = OK
    if drift or edge > 0:
        now = MODEL
    if ms[MS_N] >= mk[MK_N]:
        now = DISAGREE
    # fault_detector STUCK; a JUMP only with the disagreement (a load step on a stiff plant
    # can pass for a jump: with the position isolated the estimate then follows the
    # pressures and agrees with the measurement again, where a sensor offset keeps it away)
    if sensor_code == 2 or (sensor_code == 1 and ms[MS_N] >= mk[MK_N]):
        now = SENSOR
    if now != OK and (ms[MS_HOLD] <= 0 or now >= ms[MS_VERDICT]):
        if ms[MS_HOLD] <= 0 or now > ms[MS_VERDICT]:
            ms[MS_DET] += 1                          # a new (or more severe) verdict
        ms[MS_VERDICT] = now
        ms[MS_HOLD] = mk[MK_HOLD]
    else:
        if ms[MS_HOLD] > 0:
            ms[MS_HOLD] -= 1
        if ms[MS_HOLD] <= 0:
            ms[MS_VERDICT] = now
            if now != OK:
                ms[MS_DET] += 1
                ms[MS_HOLD] = mk[MK_HOLD]
    return int(ms[MS_VERDICT])


@njit(cache=True)
def load_variation(x, lv, alpha_m, alpha_v) -> None:
    """The pressure difference's mean over 1/alpha_m updates and its variance about that mean
    over 1/alpha_v (lv: LV_DPM, LV_DPV), read by :func:`load_varying`. A load step's deviation
    adds at most dp^2 alpha_v/(2 alpha_m) to the variance, 1/16 with the defaults: a 5 kN step,
    1.94 MPa, reaches 0.49 MPa rms, below the 0.74 MPa friction holds, so neither a held load
    nor its removal counts as varying."""
    dp = x[2] - x[3]
    lv[LV_DPM] += alpha_m * (dp - lv[LV_DPM])
    lv[LV_DPV] += alpha_v * ((dp - lv[LV_DPM]) ** 2 - lv[LV_DPV])


@njit(cache=True)
def load_varying(lv, dp_load) -> bool:
    """The pressure difference varies by more than dp_load rms (:func:`load_variation`): a
    varying load, under which leakage and compressibility flows the model gets wrong reverse
    faster than the adaptive states follow (:func:`disagree_noise`'s q_x_offset); a held one
    is :func:`flow_noise`'s."""
    return lv[LV_DPV] > dp_load * dp_load


@njit(cache=True)
def load_swinging(x, lv, dp_load, hold_ticks) -> bool:
    """The load swings: within the last ``hold_ticks`` updates (LOAD_SWING_HOLD) the pressure
    difference was more than dp_load above its mean over offset_load_mean
    (:func:`load_variation`) and also more than dp_load below it (lv[LV_ABOVE], lv[LV_BELOW]
    count down from each). A sinusoidal load does so from its first full swing on, and holds
    it through the crossings of its mean, where it moves fastest; a load step or its removal
    (one side only) does not, and neither do friction's flips under a sine without load
    (0.25 MPa rms on the nominal plant, about twice that at friction x2: the caller's band
    is LOAD_SWING_BAND x the 0.74 MPa friction holds). Read by :func:`disagree_noise`
    (q_x_offset) through :func:`swinging`."""
    dev = x[2] - x[3] - lv[LV_DPM]
    for i, beyond in ((LV_ABOVE, dev > dp_load), (LV_BELOW, dev < -dp_load)):
        if beyond:
            lv[i] = hold_ticks
        elif lv[i] > 0.0:
            lv[i] -= 1.0
    return swinging(lv)


@njit(cache=True)
def swinging(lv) -> bool:
    """The verdict of the last :func:`load_swinging`: both sides seen within the hold."""
    return lv[LV_ABOVE] > 0.0 and lv[LV_BELOW] > 0.0


@njit(cache=True)
def disagree_noise(Q, x, i_gm, position_gm_sigma, mk, ms, edge, q_x, q_x_disagree, varying,
                   q_x_offset) -> None:
    """While the disagreement condition holds (|low-passed z - x_hat| above the band for MK_N
    samples), while the DISAGREE verdict stays reported (its hold) and while an adaptive state
    sits on its bound (edge > 0: the model is beyond what it can adapt to), the position's
    process noise is q_x_disagree instead of q_x: the filter's dead reckoning is proven wrong, so
    its position variance opens and the gain pulls the estimate to the measurement
    (adjustable-level process noise, Bar-Shalom et al. 2001 sec. 11.2). Meanwhile the sensor
    offset estimate b is held within +-position_gm_sigma (its own sigma): a persistent
    disagreement is not a Gauss-Markov wander of the sensor, and with the position free b
    would otherwise keep it (it is pushed by every innovation, K_b e per tick, and decays
    only at 2 pi f_c). Under a
    varying or swinging load (``varying``: :func:`load_varying` or :func:`swinging`) it is
    q_x_offset, between the two: the leakage and compressibility flows the adaptive states get
    wrong integrate into a position error at low frequency, where b (the sensor's 1 Hz wander)
    would take it as offset; the estimate follows the sensor there instead. The swing opens it
    from the load's first full swing on (0.51 s for 5 kN at 1 Hz), where the variance test
    takes seconds: before, b took 200 um within the first negative half-wave at C_eq x10 while
    the adaptive states were still learning, and the monitor reported filter_sensor_disagree
    in 23 of 540 stiffness runs of Table 4.5 and 38 of 400 of random:200 (tuning seeds 1-2;
    Table 4.5: 7 with the filter started at rest alone, :func:`friction_input`). With both:
    none.
    Measured on Table 4.5's C_eq x10 plants under the
    stiffness scenario (issue 42's bound, tuning seeds 1-2): 65 of 108 runs meet it with b
    taking the error (q_x_offset = q_x), 107 with 3e-10 m^2 per tick. 1e-9 gave 106 and
    followed a 1.6 mm sensor jump within 3 samples under a varying load, too fast for the jump
    detector's debounce (tests/test_batch_fast.py's drift that ends in a jump)."""
    if ms[MS_N] >= mk[MK_N] or ms[MS_VERDICT] == DISAGREE or edge > 0:
        Q[0, 0] = q_x_disagree
        if i_gm >= 0:
            x[i_gm] = clip(x[i_gm], -position_gm_sigma, position_gm_sigma)
    elif varying:
        Q[0, 0] = q_x_offset
    else:
        Q[0, 0] = q_x


@njit(cache=True)
def flow_noise(Q, x, i_flow, i_gm, b_sigma, flow_gate, q_flow, rest, count, flow_ticks, fk,
               dp_friction, flow_share, flow_report) -> bool:
    """Unmodelled flow v_f (velocity units: A_p v_f into chamber A, out of B; issue 15): a
    persistent velocity bias of the flow model, which the adaptive states cannot separate at
    one operating point, is not a sensor offset. Its random walk opens (q_flow, else closed)
    while the piston rests (``rest``; the callers also require the load not to vary,
    :func:`load_varying`) and the sensor-offset estimate b has sat beyond flow_gate times its
    own stationary sigma (b_sigma: the Gauss-Markov sigma at the measured noise level) for
    flow_ticks updates in a row with the pressure difference within dp_friction of its value
    at the run's start (count: FL_N that run, FL_DP that value, FL_ACTIVE the result; a held
    load, not a sinusoidal one, whose reversing flows a walk would only chase), and it is
    projected onto

        |v_f| <= flow_share (C_x + C_r) max(0, |p_A - p_B| - dp_friction) / A_p

    the leakage flow of the pressure difference beyond what the largest friction of the
    family can hold (dp_friction): a leak needs a load. Without one the bound is zero and the
    walk stays closed, so a sensor drift while holding without load is not absorbed as flow
    and ends in DISAGREE as before; under load a drift slower than the bound cannot be told
    from a leak with one position sensor. So a flow is never absorbed silently: True (the
    monitor's MODEL verdict, model_mismatch) while |v_f| > flow_report. The arguments are
    named as the estimator.model.* parameters they come from."""
    if i_flow < 0 or i_gm < 0:
        return False
    dp = x[2] - x[3]
    if rest and abs(x[i_gm]) > flow_gate * b_sigma and (
            count[FL_N] == 0.0 or abs(dp - count[FL_DP]) <= dp_friction):
        if count[FL_N] == 0.0:
            count[FL_DP] = dp
        count[FL_N] += 1.0
    else:
        count[FL_N] = 0.0
    v_max = flow_share * (fk[FK_CX] + fk[FK_CR]) * max(0.0, abs(dp) - dp_friction) / fk[FK_AP]
    Q[i_flow, i_flow] = q_flow if count[FL_N] >= flow_ticks and v_max > 0.0 else 0.0
    x[i_flow] = clip(x[i_flow], -v_max, v_max)
    active = abs(x[i_flow]) > flow_report
    count[FL_ACTIVE] = 1.0 if active else 0.0
    return active


@njit(cache=True)
def safe_state(verdict: int) -> bool:
    """The verdict the nodes answer with the safe state (core.loop.safe_state): the position
    sensor is faulty."""
    return verdict == SENSOR


def alarm(verdict: int) -> bool:
    """The verdicts reported as ERROR: the sensor is faulty, or filter and sensor disagree
    beyond the band (the estimate then falls back on the sensor: disagree_noise)."""
    return verdict in (DISAGREE, SENSOR)


def lowpass_alpha(f_hz: float, Ts: float) -> float:
    """Per-tick weight of a first-order low-pass at f_hz; 1 (no low-pass) for f_hz <= 0."""
    return 1.0 - math.exp(-2.0 * math.pi * f_hz * Ts) if f_hz > 0 else 1.0
