"""The estimator's tick, compiled: the one implementation of what Estimator.update does on a
usable sample and of each prediction it makes; Estimator calls it per tick, the closed-loop
kernels (core.sim.closed_loop) for many ticks at once.

Python keeps the events: validity checks with their counters and reasons, the first sample,
a sensor isolated as faulty, undoing provisional (stale) predictions, the Chinniah pair.
The constants and the state are named records (:data:`CONSTANTS`, :data:`STATE`: fields named
as the parameters they come from), the other arrays are the filter's own, named in one
record (:class:`Arrays`), and the Estimator's state arrays are views into E (nothing is copied
per tick).
Order: p_D measured, predict (eq. 4.1-4.2 with eq. 4.36; the chamber filter's check-valve
state from its prior and this sample's measured pressures), p_D low-pass, Joseph update
(eq. 4.4-4.6), the adaptive parts, fault detector, consistency monitor.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..jit_cache import drop_stale
from ..kernel_records import Matrix, Vector, entry_point
from . import adapt
from . import fault_detector as fd
from . import noise_level
from .kernels import predict, update_gated, workspace_size
from .friction import friction_estimate

drop_stale(__file__)

# A chamber whose measured pressure is this many sigma of its noise below p_c sits on its check
# valve, whatever the filter's states predict (:func:`valve_state`; one sample in 44 of a
# chamber at p_c passes it; 3 left rare excursions at rest under a load, docs/nodes/estimator.md)
VALVE_GATE = 2.0

# The constants (K) and the state (E) of one estimator: one-element structured arrays whose
# fields are named as the parameters they come from (core.estimator.params, without the
# 'estimator.model.' prefix; alpha_*: a low-pass's per-tick factor, i_*: a state's index in x,
# -1 when the filter has no such state). Each kernel reads them as records: k, e = K[0], E[0].
CONSTANTS = np.dtype([
    # validity of a sample (estimator.validity.*): |position| <= x_max (half the stroke plus
    # the margin), pressures in [pressure_min, pressure_max], |motor speed| bounded
    ('x_max', 'f8'), ('pressure_min', 'f8'), ('pressure_max', 'f8'),
    ('max_abs_motor_speed', 'f8'), ('use_pressure', 'f8'), ('isolate', 'f8'),
    # the filter: model_filter (eq. 4.35 or the chamber filter) or PVA; chambers: ChamberKF
    ('model_filter', 'f8'), ('chambers', 'f8'), ('n_lin', 'f8'),
    ('alpha_pressure', 'f8'), ('alpha_friction', 'f8'), ('friction_pressure', 'f8'),
    ('A_p', 'f8'), ('D_p', 'f8'), ('F_s', 'f8'), ('v_eps', 'f8'), ('i_leak', 'f8'),
    # the chamber filter: check valves, flows (adapt.parameter_columns), adaptive states
    ('p_c', 'f8'), ('C_x', 'f8'), ('C_r', 'f8'), ('p_acc', 'f8'), ('c_Ts', 'f8'),
    ('i_leakage', 'f8'), ('leakage_range', 'f8', (2,)),
    ('i_displacement', 'f8'), ('displacement_range', 'f8', (2,)),
    ('i_compliance', 'f8'), ('compliance_range', 'f8', (2,)), ('i_friction', 'f8'),
    ('friction_range', 'f8', (2,)), ('i_external_leakage', 'f8'),
    ('external_leakage_range', 'f8', (2,)), ('i_frozen', 'f8'), ('adapt_gate', 'f8'),
    ('i_gm', 'f8'), ('offset_bound', 'f8'), ('i_moved', 'f8'), ('moved_gate', 'f8'),
    ('stribeck', 'f8'), ('friction', 'f8', (adapt.NFK,)),       # adapt.friction_input's
    # the Q schedules: the load state's (adapt.maneuver), the position noise's
    # (adapt.disagree_noise, under a varying or swinging load: adapt.load_variation,
    # adapt.load_swinging), the flow's
    # (adapt.flow_noise)
    ('i_load', 'f8'), ('q_load', 'f8'), ('q_load_jump', 'f8'), ('load_jump_z', 'f8'),
    ('load_hold', 'f8'), ('swing_band', 'f8'),     # adapt.load_swinging's hold and band
    ('q_x', 'f8'), ('q_x_disagree', 'f8'), ('position_gm_sigma', 'f8'),
    ('q_x_offset', 'f8'), ('alpha_load', 'f8', (2,)),
    ('i_flow', 'f8'), ('q_flow', 'f8'), ('flow_gate', 'f8'), ('flow_ticks', 'f8'),
    ('dp_friction', 'f8'), ('flow_share', 'f8'), ('flow_report', 'f8'),
    ('hold_rate', 'f8'),        # per tick: the published position's blend at rest under load
    # the stages with constants of their own
    ('noise_adapt', 'f8'), ('noise', 'f8', (noise_level.NNK,)),   # noise_level's
    ('monitor', 'f8', (adapt.NMK,)),                               # adapt.monitor's
    ('detector', 'f8', (fd.NFK,)),                                 # fault_detector's
])
STATE = np.dtype([
    ('omega', 'f8'),            # the previous sample's motor speed (rad/s)
    ('pd_meas', 'f8'), ('pd_filt', 'f8'),   # last good measured p_D, its low-pass (Pa)
    ('updates', 'f8'),          # measurement updates so far
    ('mode', 'f8'),             # chamber filter: check-valve state
    ('w_fric', 'f8'),           # low-passed pump speed: the friction sign of eq. 4.36
    ('edge', 'f8'),             # adaptive states on a bound after the last update
    ('p_last', 'f8', (4,)),     # chamber filter: adapt.pressure_increments' state
    ('clipped', 'f8', (1,)),    # chamber filter: updates in a row that clipped a parameter
    ('hold_weight', 'f8'),      # weight of b in the published position (:func:`published`)
    ('hold_v', 'f8'),           # the pump-flow velocity's mean over rest_time (m/s)
    ('hold_n', 'f8'),           # ticks in a row |hold_v| is below (+) or beyond (-) rest_velocity
    ('friction', 'f8', (adapt.NFS,)),           # adapt.friction_input's
    ('noise', 'f8', (noise_level.NNS,)),        # noise_level's
    ('flow', 'f8', (adapt.NFLOW,)),             # adapt.flow_noise's
    ('load', 'f8', (adapt.NLV,)),               # adapt.load_variation's
    ('monitor', 'f8', (adapt.NMS,)),            # adapt.monitor's
    ('detector', 'f8', (fd.NFS,)),              # fault_detector's
])


def new_records():
    """(K, E) of an estimator not packed yet: zeros."""
    return np.zeros(1, CONSTANTS), np.zeros(1, STATE)


class Arrays(NamedTuple):
    """The filter's own arrays the kernels work on (:func:`pack`; never copies)."""
    x: Vector           # state estimate
    P: Matrix           # its covariance
    F: Matrix           # transition of this tick (the check-valve state's, with columns)
    G: Matrix           # input matrix of this tick
    u: Vector           # input: motor speed, friction (eq. 4.36 or Stribeck)
    Q: Matrix           # process noise (adaptive parts write into it)
    tmp: Matrix         # predict's workspace
    H: Matrix           # measurement model: position and pressures
    R: Matrix           # its noise
    y: Vector           # its innovation
    S: Matrix           # its innovation covariance
    H1: Matrix          # position only (the pressures not valid)
    R1: Matrix
    y1: Vector
    S1: Matrix
    g_leak: Vector      # eq. 4.35 filter: the leakage column's sensitivities
    zm: Vector          # measurement vector (position and pressures)
    z1: Vector          # position only
    ws: Vector          # update's workspace
    Fm: Matrix          # chamber filter: stacked F of the check-valve states, leakage columns
    Gm: Matrix          # stacked G, unit-flow columns (adapt.parameter_columns)
    x_prior: Vector     # x and P before this sample's update (:func:`estimate`: a jump's
    P_prior: Matrix     # first samples are not taken)


def supported(est) -> bool:
    """The compiled path covers this estimator's configuration."""
    return est.chinniah is None


def pack(est):
    """(K, E, arrays) of an Estimator, built once when it is: K from its attributes of the
    same names, E holding a copy of its state arrays (the Estimator then uses views into
    it), the arrays the filter's own. E's scalars are set by Estimator.reset."""
    kf, d = est.kf, est.detector
    K, E = new_records()
    k, e = K[0], E[0]
    arrays = pack_filter(kf, k, e, est.is_model, est.chambers)
    for name in ('x_max', 'pressure_min', 'pressure_max', 'max_abs_motor_speed',
                 'alpha_pressure', 'alpha_friction', 'isolate', 'i_load',
                 'q_load', 'q_load_jump', 'load_jump_z', 'load_hold',
                 'q_x', 'q_x_disagree',
                 'position_gm_sigma', 'q_flow', 'flow_gate', 'flow_ticks', 'flow_share',
                 'flow_report', 'q_x_offset', 'alpha_load', 'hold_rate'):
        k[name] = getattr(est, name)
    k['use_pressure'] = est.is_model and est.kf.with_pressure   # until stop_pressures
    k['monitor'], e['monitor'] = est.monitor_k, est.monitor_s
    if est.noise_k is not None:
        k['noise_adapt'], k['noise'] = 1.0, est.noise_k
    e['noise'], e['flow'], e['load'] = est.noise_s, est.flow_s, est.load_s
    k['detector'], e['detector'] = d.k, d.s
    return K, E, arrays


def pack_filter(kf, k, e, model: bool, chambers: bool) -> Arrays:
    """The filter's part of the records k, e (K[0], E[0]) -- what :func:`predict_tick` reads:
    its model, friction, check-valve and adaptive constants and state -- and its arrays: a
    ``model`` filter (eq. 4.35, ModelKF; with ``chambers`` ChamberKF) or the PVA filter
    (neither)."""
    k['model_filter'], k['chambers'] = model, chambers
    for name in ('i_leak', 'i_leakage', 'i_displacement', 'i_compliance', 'i_gm', 'i_friction',
                 'i_external_leakage', 'i_flow', 'i_moved'):
        k[name] = -1.0
    if model:
        k['friction_pressure'] = kf.friction_uses_pressure
        k['i_leak'] = -1.0 if kf.i_leak is None else kf.i_leak
        k['n_lin'] = kf._n_lin
        c = kf.c if chambers else kf.h
        k['A_p'], k['D_p'], k['F_s'], k['v_eps'] = c.A_p, c.D_p, kf.F_s, kf.v_eps
        k['i_moved'], k['moved_gate'] = kf.i_moved, kf.moved_gate
    F, G = kf.F, kf.G
    Fm, Gm = np.zeros((1, 1)), np.zeros((1, 1))
    if chambers:
        c = kf.c
        k['p_c'], k['C_x'], k['C_r'], k['p_acc'], k['c_Ts'] = c.p_c, c.C_x, c.C_r, c.p_acc, kf.c_Ts
        for name in ('i_leakage', 'leakage_range', 'i_displacement', 'displacement_range',
                     'i_compliance', 'compliance_range', 'i_friction', 'friction_range',
                     'i_external_leakage', 'external_leakage_range', 'i_gm', 'offset_bound',
                     'i_frozen', 'adapt_gate',
                     'i_flow', 'dp_friction'):
            k[name] = getattr(kf, name)
        k['swing_band'] = adapt.LOAD_SWING_BAND * kf.dp_friction
        e['edge'], e['p_last'], e['clipped'], e['mode'] = kf.edge, kf.p_last, kf.clipped, kf.mode
        if kf.fk is not None:
            k['stribeck'], k['friction'], e['friction'] = 1.0, kf.fk, kf.fs
        # F, G: the filter's own, overwritten per tick with the mode's pair
        # Gm: the stacked G (3 columns) then the unit-flow columns of adapt.parameter_columns
        # Fm: the stacked F, then the leakage sensitivities of lambda and epsilon
        # (adapt.predict_jacobian)
        Fm = np.hstack((np.vstack([f for f, _ in kf.modes]), kf.Dm))
        Gm = np.hstack((np.vstack([g for _, g in kf.modes]), kf.Lm))
    if model:
        u = kf.u
        g_leak = kf._g_leak if kf.i_leak is not None else np.zeros(1)
        H1, R1, y1, S1 = kf.H1, kf.R1, kf._y1, kf._S1
    else:
        u, g_leak = kf._u, np.zeros(1)
        H1, R1, y1, S1 = kf.H, kf.R, kf.y, kf.S
    ws = np.zeros(workspace_size(len(kf.x), 3))
    return Arrays(kf.x, kf.P, F, G, u, kf.Q, kf._tmp, kf.H, kf.R, kf.y, kf.S, H1, R1, y1, S1,
                  g_leak, np.zeros(kf.H.shape[0]), np.zeros(1), ws, Fm, Gm,
                  np.zeros_like(kf.x), np.zeros_like(kf.P))


def predict_filter(kf, chambers: bool, omega: float, p_D: float | None,
                   w_friction: float | None) -> None:
    """ModelKF / ChamberKF (``chambers``).predict, a filter on its own: :func:`predict_given`.
    The filter's constants and arrays are packed once (kf._alone); its state (check-valve
    mode, pressure increments, friction model) is passed in and taken back on each call."""
    if getattr(kf, '_alone', None) is None:
        K, E = new_records()
        a = pack_filter(kf, K[0], E[0], True, chambers)  # alpha_friction 0: w_friction as given
        kf._alone = K, E, a, entry_point(predict_given, K, E, a, 0.0, 0.0, True, 0.0)
    K, E, a, predict = kf._alone
    if chambers:
        E['p_last'], E['friction'] = kf.p_last, kf.fs
    predict(K, E, a, float(omega), float(omega if w_friction is None else w_friction),
            p_D is not None, 0.0 if p_D is None else float(p_D))
    if chambers:
        kf.p_last[:], kf.fs[:] = E['p_last'][0], E['friction'][0]
        kf.mode = int(E['mode'][0])


@njit(cache=True)
def predict_given(K, E, a, omega, w_friction, use_p, p_D) -> None:
    """:func:`predict_tick` with the inputs the estimator filters given as they are: the speed
    held at ``omega`` over the period, the friction's speed ``w_friction``, the measured
    ``p_D`` (``use_p`` False: the filter's own)."""
    k, e = K[0], E[0]
    e.omega = omega                  # the period's mean speed: (omega + omega) / 2
    e.w_fric = w_friction
    k.use_pressure = use_p
    e.pd_filt = p_D
    predict_tick(K, E, a, omega, np.nan, np.nan)


@njit(cache=True)
def position_fault(E) -> bool:
    """This tick's consistency verdict calls for the safe state (core.loop.safe_state)."""
    return adapt.safe_state(int(E[0].monitor[adapt.MS_VERDICT]))


@njit(cache=True)
def ready(K, E, position, w, pa, pb) -> bool:
    """This measurement takes the common path (nothing to count, no reason to report)."""
    k, code = K[0], int(E[0].detector[fd.FS_CODE])
    if not (math.isfinite(w) and abs(w) <= k.max_abs_motor_speed):
        return False
    if not (math.isfinite(position) and abs(position) <= k.x_max):
        return False
    if k.use_pressure > 0.5 and not pressure_ok(k, pa, pb):
        return False
    return not (k.isolate > 0.5 and (code == fd.JUMP or code == fd.STUCK))


@njit(cache=True)
def pressure_ok(k, pa, pb) -> bool:
    return reading_ok(k, pa) and reading_ok(k, pb)


@njit(cache=True)
def reading_ok(k, p) -> bool:
    """One chamber pressure reading is finite and in [pressure_min, pressure_max]."""
    return math.isfinite(p) and k.pressure_min <= p <= k.pressure_max


@njit(cache=True)
def valve_state(k, e, R, Fm, Gm, n, col0, x, u, omega, pa, pb) -> int:
    """The chamber filter's check-valve state for this tick, 2 s_A + s_B (index into the
    stacked Fm, Gm). A valve is open while its chamber's prior pressure is below p_c (where the
    valve's linear flow is an inflow), unless the tick's flows would lift the chamber above p_c
    with the valve shut: a check valve passes no reverse flow, and the open mode's linear
    conductance would hand the pump's flow back to the accumulator for as long as the prior
    sat below p_c (at a reversal the filling chamber lost 30 um of piston travel on a stiff
    oil, beta x1.4). That prediction is the filter's own; where this sample's measured pressure
    (pa, pb; NaN: none) is below p_c by :data:`VALVE_GATE` sigma of its noise (R), the
    chamber is on its valve whatever the states predict, and it stays open."""
    s_a, s_b = x[2] < k.p_c, x[3] < k.p_c
    on_a = pa < k.p_c - VALVE_GATE * math.sqrt(R[1, 1])
    on_b = pb < k.p_c - VALVE_GATE * math.sqrt(R[2, 2])
    if s_a and not on_a and shut_pressure(k, e, Fm, Gm, n, col0, s_b, 2, x, u, omega) >= k.p_c:
        s_a = False
    if s_b and not on_b and shut_pressure(k, e, Fm, Gm, n, col0, 2 * s_a, 3, x, u,
                                          omega) >= k.p_c:
        s_b = False
    return 2 * s_a + s_b


@njit(cache=True)
def shut_pressure(k, e, Fm, Gm, n, col0, mode, row, x, u, omega) -> float:
    """Chamber pressure x[row] (2: p_A, 3: p_B) after one tick of the mean prediction in
    check-valve state ``mode`` (that chamber's valve shut): the model's row, the friction
    scale's column and the adaptive states' flows (adapt.parameter_flows) through the ZOH
    columns of a unit flow (Gm[:, col0], Gm[:, col0 + 1])."""
    r = mode * n + row
    p = 0.0
    for j in range(n):
        p += Fm[r, j] * x[j]
    for j in range(col0):
        p += Gm[r, j] * u[j]
    if k.i_friction >= 0:                      # the row of adapt.friction_column
        p += adapt.friction_entry(Gm[r, 1], e.friction) * x[int(k.i_friction)]
    pl = e.p_last                              # adapt.pressure_increments, not yet moved on
    fa, fb = adapt.parameter_flows(x, int(k.i_leakage), int(k.i_displacement),
                                   int(k.i_compliance), int(k.i_external_leakage), x[2], x[3],
                                   x[2] - pl[0], x[3] - pl[1], omega, k.C_x, k.C_r, k.p_acc,
                                   k.D_p, k.c_Ts)
    return p + Gm[r, col0] * fa + Gm[r, col0 + 1] * fb


@njit(cache=True)
def predict_tick(K, E, a, w, pa, pb):
    """One prediction over Ts with the motor speed averaged over the period (its previous
    value and ``w``): the model's inputs (eq. 4.36 friction, or the chamber filter's Stribeck
    curve, its check-valve state, friction and parameter columns), then eq. 4.1-4.2 (with the
    leakage Jacobian when lambda is a state). Chamber filter: (F, G) of the check-valve state
    (:func:`valve_state`, with this sample's measured ``pa``, ``pb``; NaN: none) are copied
    from the stacked Fm, Gm. ``a``: the :class:`Arrays`."""
    k, e = K[0], E[0]
    x, P, F, G, u, Q, tmp, g_leak, ws, Fm, Gm = (a.x, a.P, a.F, a.G, a.u, a.Q, a.tmp,
                                                 a.g_leak, a.ws, a.Fm, a.Gm)
    omega = 0.5 * (e.omega + w)
    e.omega = w
    use_p = k.use_pressure > 0.5
    if k.model_filter > 0.5:                  # chamber filters are model filters too
        e.w_fric += k.alpha_friction * (omega - e.w_fric)
    if k.chambers > 0.5:
        u[0] = omega
        if k.stribeck > 0.5:
            u[1] = adapt.friction_input(k.friction, e.friction, x, omega)
        else:
            pd = e.pd_filt if use_p else x[2] - x[3]
            u[1] = friction_estimate(e.w_fric, pd, k.friction_pressure > 0.5, k.A_p, k.D_p,
                                     k.F_s, k.v_eps)
        n = x.shape[0]
        mode = valve_state(k, e, a.R, Fm, Gm, n, G.shape[1], x, u, omega, pa, pb)
        e.mode = mode
        for i in range(n):
            for j in range(n):
                F[i, j] = Fm[mode * n + i, j]
            for j in range(G.shape[1]):
                G[i, j] = Gm[mode * n + i, j]
        adapt.friction_column(F, G, int(k.n_lin), int(k.i_friction), e.friction)
        if k.i_leakage >= 0 or k.i_displacement >= 0 or k.i_compliance >= 0:
            pl = e.p_last
            adapt.pressure_increments(pl, x[2], x[3])
            adapt.parameter_columns(F, Gm, mode * n, G.shape[1], int(k.n_lin),
                                    int(k.i_leakage), int(k.i_displacement),
                                    int(k.i_compliance), int(k.i_external_leakage), x[2], x[3],
                                    pl[2], pl[3], omega, k.C_x, k.C_r, k.p_acc, k.D_p, k.c_Ts)
    elif k.model_filter > 0.5:
        u[0] = omega
        has_pd = use_p and k.friction_pressure > 0.5
        u[1] = friction_estimate(e.w_fric, e.pd_filt, has_pd, k.A_p, k.D_p, k.F_s,
                                 k.v_eps)
        il = int(k.i_leak)
        if il >= 0:
            pd = e.pd_filt if use_p else x[2]
            for i in range(int(k.n_lin)):
                F[i, il] = g_leak[i] * pd
    il = int(k.i_leakage)
    if k.chambers > 0.5 and il >= 0:
        n = x.shape[0]
        ie = int(k.i_external_leakage)
        adapt.predict_jacobian(x, P, F, ws[:n * n].reshape((n, n)), Fm, int(e.mode) * n, n,
                               2 * n, int(k.n_lin), x[il], x[ie] if ie >= 0 else 0.0, G, u,
                               Q, tmp)
    else:
        predict(x, P, F, G, u, Q, tmp)


@njit(cache=True)
def advance(K, E, a, w, pa, pb) -> bool:
    """A sample's prediction: its p_D (when the pressures are valid), :func:`predict_tick`
    with ``w`` (and the pressures, when valid and used), the p_D low-pass. Returns whether the
    pressures are valid."""
    k, e = K[0], E[0]
    pr_ok = pressure_ok(k, pa, pb)
    if pr_ok:
        e.pd_meas = pa - pb
    if pr_ok and k.use_pressure > 0.5:
        predict_tick(K, E, a, w, pa, pb)
    else:
        predict_tick(K, E, a, w, np.nan, np.nan)
    if pr_ok:
        e.pd_filt += k.alpha_pressure * (e.pd_meas - e.pd_filt)
    return pr_ok


@njit(cache=True)
def consistency(K, E, a, position) -> int:
    """The consistency monitor's verdict on this sample (adapt.monitor); the chamber filter's
    position noise follows the disagreement (adapt.disagree_noise)."""
    k, e = K[0], E[0]
    x, Q = a.x, a.Q
    code = int(e.detector[fd.FS_CODE])
    flow = e.flow[adapt.FL_ACTIVE] > 0.5
    v = adapt.monitor(k.monitor, e.monitor, position, x[0], code, code == fd.DRIFT or flow,
                      int(e.edge))
    if k.chambers > 0.5:
        adapt.disagree_noise(Q, x, int(k.i_gm), k.position_gm_sigma, k.monitor, e.monitor,
                             int(e.edge), k.q_x, k.q_x_disagree,
                             adapt.load_varying(e.load, k.dp_friction)
                             or adapt.swinging(e.load), k.q_x_offset)
    return v


@njit(cache=True)
def estimate(K, E, a, position, w, i, pa, pb):
    """Estimator.update on a usable position sample (``w``: the speed it takes, the held one
    when the sample's is not valid; ``i``: the active motor's current for the fault
    detector's torque balance, NaN with a held speed or none; invalid pressures are left
    out): :func:`advance`, the update with position (and pressures), the adaptive parts, the
    fault detector and :func:`consistency`. Returns (position, innovation, nis, nis_dim,
    code); nis_dim 0 when the update was held back (a suspected jump's sample)."""
    k, e = K[0], E[0]
    pr_ok = advance(K, E, a, w, pa, pb)
    x, P, Q, H, R, y, S, H1, R1, y1, S1, zm, z1, ws = (a.x, a.P, a.Q, a.H, a.R, a.y, a.S, a.H1,
                                                       a.R1, a.y1, a.S1, a.zm, a.z1, a.ws)
    use_p = k.use_pressure > 0.5
    if k.noise_adapt > 0.5:
        noise_level.update(k.noise, e.noise, position, pa, pb, pr_ok and use_p, w, R, R1, Q)
    a.x_prior[:] = x
    a.P_prior[:] = P
    if pr_ok and use_p:
        zm[0] = position
        if k.chambers > 0.5:
            zm[1] = pa
            zm[2] = pb
        else:
            zm[1] = e.pd_meas
        nis = update_gated(x, P, H, R, zm, y, S, ws, int(k.i_frozen), k.adapt_gate,
                           int(k.i_moved), k.moved_gate)
        innov, s00, m = y[0], S[0, 0], zm.shape[0]
        pz = fd.pressure_z(y, S, m)
    else:
        z1[0] = position
        nis = update_gated(x, P, H1, R1, z1, y1, S1, ws, int(k.i_frozen), k.adapt_gate,
                           -1, 0.0)
        innov, s00, m = y1[0], S1[0, 0], 1
        pz = 0.0
    # the fault detector's pressures: each valid reading (one may be valid without the other)
    pa_ok = pa if use_p and reading_ok(k, pa) else math.nan
    pb_ok = pb if use_p and reading_ok(k, pb) else math.nan
    # the shaft's p_D through the pump's displacement as learned (adapt_displacement's delta)
    displacement = 1.0 + x[int(k.i_displacement)] if k.i_displacement >= 0 else 1.0
    fd.detect(k.detector, e.detector, position, innov, s00, pz, pa_ok, pb_ok,
              w if i == i else math.nan, i, displacement)
    if k.isolate > 0.5 and fd.suspect(k.detector, e.detector):
        # a jump's first samples, until the detector's debounce decides: this update is
        # undone (isolate's predict only). Under a varying load the position noise is open
        # (adapt.disagree_noise) and the gain took 78 % of a 1 mm sensor jump on its first
        # sample: the innovation fell under the threshold before the debounce, the jump went
        # unreported and the loop moved the piston by the bias
        x[:] = a.x_prior
        P[:] = a.P_prior
        e.detector[fd.FS_SUSPECT] += 1
        m = 0                  # no update: nis_dim 0, published with update_skipped
    else:
        e.updates += 1
        if k.chambers > 0.5:
            lam, dlt, kap = k.leakage_range, k.displacement_range, k.compliance_range
            phi, eps = k.friction_range, k.external_leakage_range
            e.edge = adapt.project(x, int(k.i_leakage), lam[0], lam[1], int(k.i_displacement),
                                   dlt[0], dlt[1], int(k.i_compliance), kap[0], kap[1],
                                   int(k.i_friction), phi[0], phi[1],
                                   int(k.i_external_leakage), eps[0], eps[1], int(k.i_gm),
                                   k.offset_bound, e.clipped, adapt.EDGE_TICKS)
    if k.chambers > 0.5:
        # does the load swing? (read by consistency: the position noise)
        adapt.load_swinging(x, e.load, k.swing_band, k.load_hold)
        adapt.maneuver(Q, int(k.i_load), pz, k.load_jump_z,
                       k.q_load + e.friction[adapt.FS_Q], k.q_load_jump)
        b_sigma = k.position_gm_sigma * e.noise[noise_level.NS_SX]
        adapt.load_variation(x, e.load, k.alpha_load[0], k.alpha_load[1])
        held = not adapt.load_varying(e.load, k.dp_friction)
        rest = (k.stribeck > 0.5 and e.friction[adapt.FS_N] >= k.friction[adapt.FK_NREST]
                and held)
        hold_blend(e, k, k.stribeck > 0.5 and held and abs(x[2] - x[3]) > k.dp_friction)
        adapt.flow_noise(
            Q, x, int(k.i_flow), int(k.i_gm), b_sigma, k.flow_gate, k.q_flow, rest, e.flow,
            k.flow_ticks, k.friction, k.dp_friction, k.flow_share, k.flow_report)
    consistency(K, E, a, position)
    return published(E, x, int(k.i_gm)), innov, nis, m, int(e.detector[fd.FS_CODE])


@njit(cache=True)
def leak_flow(K, x) -> float:
    """The estimate's leak flow (adapt.leak_flow; m^3/s): the chamber filter's, NaN for the
    filters without chamber pressures (eq. 4.35, PVA)."""
    k = K[0]
    if k.chambers < 0.5:
        return math.nan
    return adapt.leak_flow(x, int(k.i_leakage), int(k.i_external_leakage), k.C_x, k.C_r,
                           k.p_acc)


@njit(cache=True)
def hold_blend(e, k, loaded) -> None:
    """One tick of e.hold_weight, the weight of b in the published position (:func:`published`;
    hold_v and hold_n are its state). The piston's motion is judged on the pump-flow velocity
    averaged over rest_time (hold_v; its 50 Hz low-pass alone crosses rest_velocity on the
    speed sensor's noise): b is blended in while a held load beyond what friction holds is on
    (``loaded``; the Stribeck input's velocity needed) and |hold_v| has stayed below
    rest_velocity for rest_time, out once that load lets go or varies, or |hold_v| has stayed
    beyond rest_velocity for rest_time."""
    n_rest = k.friction[adapt.FK_NREST]
    e.hold_v += (e.friction[adapt.FS_V] - e.hold_v) / max(n_rest, 1.0)
    if abs(e.hold_v) < k.friction[adapt.FK_VREST]:
        e.hold_n = max(e.hold_n, 0.0) + 1.0
    else:
        e.hold_n = min(e.hold_n, 0.0) - 1.0
    if loaded and e.hold_n >= n_rest:
        r = k.hold_rate
    elif not loaded or e.hold_n <= -n_rest:
        r = -k.hold_rate
    else:
        r = 0.0
    e.hold_weight = min(1.0, max(0.0, e.hold_weight + r))


@njit(cache=True)
def published(E, x, i_gm) -> float:
    """The position the estimate publishes: x_hat, and at rest under a held load (blended in
    and out) x_hat + b, the sensor's reading without its white noise."""
    if i_gm < 0:
        return x[0]
    return x[0] + E[0].hold_weight * x[i_gm]
