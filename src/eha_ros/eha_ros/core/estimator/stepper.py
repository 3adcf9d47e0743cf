"""The estimator's tick, compiled: the one implementation of what Estimator.update does on a
usable sample and of each prediction it makes; Estimator calls it per tick, the closed-loop
kernels (core.sim.closed_loop) for many ticks at once.

Python keeps the events: validity checks with their counters and reasons, the first sample,
a sensor isolated as faulty, undoing provisional (stale) predictions, the Chinniah pair.
Scalars live in a state vector (E_*) and the constants in K_*; the other arrays are the
filter's own, named in one record (:class:`Arrays`), and the Estimator's state arrays are views
into E (nothing is copied per tick).
Order: p_D measured, predict (eq. 4.1-4.2 with eq. 4.36), p_D low-pass, Joseph update
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

# constants
(K_XMAX, K_PMIN, K_PMAX, K_WMAX, K_ALPHA_PD, K_MODEL, K_USE_P, K_FRIC_P, K_ILEAK, K_NLIN,
 K_AP, K_DP, K_FS, K_VEPS, K_ISOLATE, K_CHAMBERS, K_PC, K_ALPHA_WF,
 K_CX, K_CR, K_PACC, K_ILAM, K_IDEL, K_LAMLO, K_LAMHI, K_DELLO, K_DELHI, K_IGM, K_BMAX,
 K_IKAP, K_KAPLO, K_KAPHI, K_CTS, K_IFROZEN, K_GATE,
 K_ILOAD, K_QLOAD, K_QLOADJ, K_LOADZ, K_ALPHA_DP, K_QX, K_QXD, K_BDIS, K_PEXC) = range(44)
K_MON = 44             # adapt.NMK entries: the consistency monitor's constants
(K_STRIBECK, K_IPHI, K_PHILO, K_PHIHI, K_IEPS, K_EPSLO, K_EPSHI, K_IMOVED,
 K_MOVEDZ) = range(K_MON + adapt.NMK, K_MON + adapt.NMK + 9)
K_FK = K_MOVEDZ + 1    # adapt.NFK entries: the friction model's constants
K_NADAPT = K_FK + adapt.NFK     # 1: the sensors' noise level is measured (noise_level)
K_NL = K_NADAPT + 1    # noise_level.NNK entries: its constants
K_IFLOW = K_NL + noise_level.NNK
K_QFLOW, K_FLOWK, K_FLOWN, K_FLOWDP, K_FLOWSH, K_FLOWREP = (K_IFLOW + i for i in range(1, 7))
K_OFFG, K_QXO = K_FLOWREP + 1, K_FLOWREP + 2     # adapt.offset_noise: gate, position noise
K_OFFA = K_QXO + 1     # 3 entries: its alphas (b, the pressure difference's mean, variance)
K_HOLDR = K_OFFA + 3   # per-tick rate of the published position's blend at rest under load
K_FD = K_HOLDR + 1     # fd.NFK entries: the fault detector's constants
NK = K_FD + fd.NFK
# state
E_OMEGA, E_PD_MEAS, E_PD_FILT, E_UPDATES, E_MODE, E_WFRIC, E_EDGE = range(7)
# E_MODE: check-valve state of the chamber filter; E_WFRIC: low-passed pump speed (friction
# sign); E_EDGE: adaptive states on a bound after the last update
E_PLAST = 7            # 4 entries: chamber filter's adapt.pressure_increments state
E_CLIPPED = 11         # chamber filter: updates in a row that clipped a parameter
E_MON = 12             # adapt.NMS entries: the consistency monitor's state
E_FS = E_MON + adapt.NMS   # adapt.NFS entries: the friction model's state
E_NL = E_FS + adapt.NFS    # noise_level.NNS entries: the noise level's state
E_FLOWN = E_NL + noise_level.NNS   # adapt.NFLOW entries: adapt.flow_noise's state
E_OFFS = E_FLOWN + adapt.NFLOW    # adapt.NOFS entries: adapt.offset_noise's state
E_FD = E_OFFS + adapt.NOFS        # fd.NFS entries: the fault detector's state
E_HOLDW = E_FD + fd.NFS  # weight of b in the published position (:func:`published`)
NE = E_HOLDW + 1
E_CODE = E_FD + fd.FS_CODE


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


def supported(est) -> bool:
    """The compiled path covers this estimator's configuration."""
    return est.chinniah is None


def pack(est):
    """(constants, state, arrays) of an Estimator, built once when it is: the state holds a copy
    of its state arrays (the Estimator then uses views into it), the arrays are the
    filter's own. Its scalars (E_OMEGA .. E_UPDATES) are set by Estimator.reset."""
    kf, d = est.kf, est.detector
    k = np.zeros(NK)
    e = np.zeros(NE)
    arrays = pack_filter(kf, k, e, est.is_model, est.chambers)
    k[K_XMAX], k[K_PMIN], k[K_PMAX], k[K_WMAX] = est.x_max, est.p_min, est.p_max, est.w_max
    k[K_ALPHA_PD], k[K_ALPHA_WF] = est.alpha_pd, est.alpha_wf
    k[K_USE_P] = est.use_pressure
    k[K_ISOLATE] = est.isolate
    k[K_ILOAD], k[K_QLOAD], k[K_QLOADJ], k[K_LOADZ] = (est.i_load, est.q_load,
                                                      est.q_load_jump, est.load_jump_z)
    k[K_QX], k[K_QXD], k[K_BDIS] = est.q_x, est.q_x_disagree, est.b_dis
    k[K_MON:K_MON + adapt.NMK] = est.monitor_k
    e[E_MON:E_MON + adapt.NMS] = est.monitor_s
    if est.noise_k is not None:
        k[K_NADAPT] = 1.0
        k[K_NL:K_NL + noise_level.NNK] = est.noise_k
    e[E_NL:E_NL + noise_level.NNS] = est.noise_s
    k[K_QFLOW], k[K_FLOWK], k[K_FLOWN] = est.q_flow, est.flow_k, est.flow_n
    k[K_FLOWSH], k[K_FLOWREP] = est.flow_share, est.flow_report
    e[E_FLOWN:E_FLOWN + adapt.NFLOW] = est.flow_s
    k[K_OFFG], k[K_QXO] = est.offset_gate, est.q_x_offset
    k[K_OFFA:K_OFFA + 3] = est.offset_alpha
    k[K_HOLDR] = est.hold_rate
    e[E_OFFS:E_OFFS + adapt.NOFS] = est.offset_s
    k[K_FD:K_FD + fd.NFK] = d.k
    e[E_FD:E_FD + fd.NFS] = d.s
    return k, e, arrays


def pack_filter(kf, k, e, model: bool, chambers: bool) -> Arrays:
    """The filter's part of (k, e) -- what :func:`predict_tick` reads: its model, friction,
    check-valve and adaptive constants and state -- and its arrays: a ``model`` filter (eq.
    4.35, ModelKF; with ``chambers`` ChamberKF) or the PVA filter (neither)."""
    k[K_MODEL], k[K_CHAMBERS] = model, chambers
    k[K_ILEAK] = -1.0
    if model:
        k[K_FRIC_P] = kf.friction_uses_pressure
        k[K_ILEAK] = -1.0 if kf.i_leak is None else kf.i_leak
        k[K_NLIN] = kf._n_lin
        c = kf.c if chambers else kf.h
        k[K_AP], k[K_DP], k[K_FS], k[K_VEPS] = c.A_p, c.D_p, kf.F_s, kf.v_eps
    k[K_ILAM] = k[K_IDEL] = k[K_IKAP] = k[K_IGM] = k[K_IPHI] = k[K_IEPS] = -1.0
    k[K_IFLOW], k[K_FLOWDP] = -1.0, 0.0
    F, G = kf.F, kf.G
    Fm, Gm = np.zeros((1, 1)), np.zeros((1, 1))
    if chambers:
        k[K_PC] = kf.c.p_c
        k[K_CX], k[K_CR], k[K_PACC] = kf.c.C_x, kf.c.C_r, kf.c.p_acc
        k[K_ILAM], k[K_IDEL], k[K_IGM], k[K_BMAX] = kf.i_lam, kf.i_del, kf.i_gm, kf.offset_bound
        (k[K_LAMLO], k[K_LAMHI]), (k[K_DELLO], k[K_DELHI]) = kf.lam_range, kf.del_range
        k[K_IKAP], (k[K_KAPLO], k[K_KAPHI]), k[K_CTS] = kf.i_kap, kf.kap_range, kf.c_Ts
        e[E_EDGE] = kf.edge
        k[K_IFROZEN], k[K_GATE] = kf.i_frozen, kf.adapt_gate
        k[K_PEXC] = kf.p_excite
        e[E_PLAST:E_PLAST + 4] = kf.p_last
        e[E_CLIPPED] = kf.clipped[0]
        k[K_ALPHA_DP] = kf.alpha_dp
        k[K_IPHI], (k[K_PHILO], k[K_PHIHI]) = kf.i_phi, kf.phi_range
        k[K_IEPS], (k[K_EPSLO], k[K_EPSHI]) = kf.i_eps, kf.eps_range
        if kf.fk is not None:
            k[K_STRIBECK] = 1.0
            k[K_FK:K_FK + adapt.NFK] = kf.fk
            e[E_FS:E_FS + adapt.NFS] = kf.fs
        k[K_IFLOW], k[K_FLOWDP] = kf.i_flow, kf.dp_friction
        e[E_MODE] = kf.mode
        # F, G: the filter's own, overwritten per tick with the mode's pair
        # Gm: the stacked G (3 columns) then the unit-flow columns of adapt.parameter_columns
        # Fm: the stacked F, then the leakage sensitivities of lambda and epsilon
        # (adapt.predict_jacobian)
        Fm = np.hstack((np.vstack([f for f, _ in kf.modes]), kf.Dm))
        Gm = np.hstack((np.vstack([g for _, g in kf.modes]), kf.Lm))
    k[K_IMOVED], k[K_MOVEDZ] = (kf.i_moved, kf.moved_gate) if model else (-1.0, 0.0)
    if model:
        u = kf.u
        g_leak = kf._g_leak if kf.i_leak is not None else np.zeros(1)
        H1, R1, y1, S1 = kf.H1, kf.R1, kf._y1, kf._S1
    else:
        u, g_leak = kf._u, np.zeros(1)
        H1, R1, y1, S1 = kf.H, kf.R, kf.y, kf.S
    ws = np.zeros(workspace_size(len(kf.x), 3))
    return Arrays(kf.x, kf.P, F, G, u, kf.Q, kf._tmp, kf.H, kf.R, kf.y, kf.S, H1, R1, y1, S1,
                  g_leak, np.zeros(kf.H.shape[0]), np.zeros(1), ws, Fm, Gm)


def predict_filter(kf, chambers: bool, omega: float, p_D: float | None,
                   w_friction: float | None) -> None:
    """ModelKF / ChamberKF (``chambers``).predict, a filter on its own: :func:`predict_given`.
    The filter's constants and arrays are packed once (kf._alone); its state (check-valve
    mode, pressure increments, friction model) is passed in and taken back on each call."""
    if getattr(kf, '_alone', None) is None:
        k, e = np.zeros(NK), np.zeros(NE)
        a = pack_filter(kf, k, e, True, chambers)       # K_ALPHA_WF 0: w_friction as given
        kf._alone = k, e, a, entry_point(predict_given, k, e, a, 0.0, 0.0, True, 0.0)
    k, e, a, predict = kf._alone
    if chambers:
        e[E_PLAST:E_PLAST + 4], e[E_FS:E_FS + adapt.NFS] = kf.p_last, kf.fs
    predict(k, e, a, float(omega), float(omega if w_friction is None else w_friction),
            p_D is not None, 0.0 if p_D is None else float(p_D))
    if chambers:
        kf.p_last[:], kf.fs[:] = e[E_PLAST:E_PLAST + 4], e[E_FS:E_FS + adapt.NFS]
        kf.mode = int(e[E_MODE])


@njit(cache=True)
def predict_given(k, e, a, omega, w_friction, use_p, p_D) -> None:
    """:func:`predict_tick` with the inputs the estimator filters given as they are: the speed
    held at ``omega`` over the period, the friction's speed ``w_friction``, the measured
    ``p_D`` (``use_p`` False: the filter's own)."""
    e[E_OMEGA] = omega                  # the period's mean speed: (omega + omega) / 2
    e[E_WFRIC] = w_friction
    k[K_USE_P] = use_p
    e[E_PD_FILT] = p_D
    predict_tick(k, e, a, omega)


@njit(cache=True)
def position_fault(e) -> bool:
    """This tick's consistency verdict calls for the safe state (core.loop.safe_state)."""
    return adapt.safe_state(int(e[E_MON + adapt.MS_VERDICT]))


@njit(cache=True)
def ready(k, e, position, w, pa, pb) -> bool:
    """This measurement takes the common path (nothing to count, no reason to report)."""
    if not (math.isfinite(w) and abs(w) <= k[K_WMAX]):
        return False
    if not (math.isfinite(position) and abs(position) <= k[K_XMAX]):
        return False
    if k[K_USE_P] > 0.5 and not pressure_ok(k, pa, pb):
        return False
    return not (k[K_ISOLATE] > 0.5 and (e[E_CODE] == fd.JUMP or e[E_CODE] == fd.STUCK))


@njit(cache=True)
def pressure_ok(k, pa, pb) -> bool:
    return (math.isfinite(pa) and k[K_PMIN] <= pa <= k[K_PMAX] and
            math.isfinite(pb) and k[K_PMIN] <= pb <= k[K_PMAX])


@njit(cache=True)
def predict_tick(k, e, a, w):
    """One prediction over Ts with the motor speed averaged over the period (its previous
    value and ``w``): the model's inputs (eq. 4.36 friction, or the chamber filter's Stribeck
    curve, its check-valve state, friction and parameter columns), then eq. 4.1-4.2 (with the
    leakage Jacobian when lambda is a state). Chamber filter: (F, G) of the check-valve state
    are copied from the stacked Fm, Gm. ``a``: the :class:`Arrays`."""
    x, P, F, G, u, Q, tmp, g_leak, ws, Fm, Gm = (a.x, a.P, a.F, a.G, a.u, a.Q, a.tmp,
                                                 a.g_leak, a.ws, a.Fm, a.Gm)
    omega = 0.5 * (e[E_OMEGA] + w)
    e[E_OMEGA] = w
    use_p = k[K_USE_P] > 0.5
    if k[K_MODEL] > 0.5:                  # chamber filters are model filters too
        e[E_WFRIC] += k[K_ALPHA_WF] * (omega - e[E_WFRIC])
    if k[K_CHAMBERS] > 0.5:
        u[0] = omega
        if k[K_STRIBECK] > 0.5:
            u[1] = adapt.friction_input(k[K_FK:K_FK + adapt.NFK], e[E_FS:E_FS + adapt.NFS], x,
                                        omega)
        else:
            pd = e[E_PD_FILT] if use_p else x[2] - x[3]
            u[1] = friction_estimate(e[E_WFRIC], pd, k[K_FRIC_P] > 0.5, k[K_AP], k[K_DP],
                                     k[K_FS], k[K_VEPS])
        mode = 2 * (x[2] < k[K_PC]) + (x[3] < k[K_PC])
        e[E_MODE] = mode
        n = x.shape[0]
        for i in range(n):
            for j in range(n):
                F[i, j] = Fm[mode * n + i, j]
            for j in range(G.shape[1]):
                G[i, j] = Gm[mode * n + i, j]
        adapt.friction_column(F, G, int(k[K_NLIN]), int(k[K_IPHI]), e[E_FS:E_FS + adapt.NFS])
        if k[K_ILAM] >= 0 or k[K_IDEL] >= 0 or k[K_IKAP] >= 0:
            pl = e[E_PLAST:E_PLAST + 4]
            adapt.pressure_increments(pl, x[2], x[3], k[K_ALPHA_DP])
            adapt.parameter_columns(F, Gm, mode * n, G.shape[1], int(k[K_NLIN]),
                                    int(k[K_ILAM]), int(k[K_IDEL]), int(k[K_IKAP]),
                                    int(k[K_IEPS]), x[2], x[3], pl[2], pl[3], omega, k[K_CX],
                                    k[K_CR], k[K_PACC], k[K_DP], k[K_CTS])
    elif k[K_MODEL] > 0.5:
        u[0] = omega
        has_pd = use_p and k[K_FRIC_P] > 0.5
        u[1] = friction_estimate(e[E_WFRIC], e[E_PD_FILT], has_pd, k[K_AP], k[K_DP], k[K_FS],
                                 k[K_VEPS])
        il = int(k[K_ILEAK])
        if il >= 0:
            pd = e[E_PD_FILT] if use_p else x[2]
            for i in range(int(k[K_NLIN])):
                F[i, il] = g_leak[i] * pd
    il = int(k[K_ILAM])
    if k[K_CHAMBERS] > 0.5 and il >= 0:
        n = x.shape[0]
        ie = int(k[K_IEPS])
        adapt.predict_jacobian(x, P, F, ws[:n * n].reshape((n, n)), Fm, int(e[E_MODE]) * n, n,
                               2 * n, int(k[K_NLIN]), x[il], x[ie] if ie >= 0 else 0.0, G, u,
                               Q, tmp)
    else:
        predict(x, P, F, G, u, Q, tmp)


@njit(cache=True)
def advance(k, e, a, w, pa, pb) -> bool:
    """A sample's prediction: its p_D (when the pressures are valid), :func:`predict_tick`
    with ``w``, the p_D low-pass. Returns whether the pressures are valid."""
    pr_ok = pressure_ok(k, pa, pb)
    if pr_ok:
        e[E_PD_MEAS] = pa - pb
    predict_tick(k, e, a, w)
    if pr_ok:
        e[E_PD_FILT] += k[K_ALPHA_PD] * (e[E_PD_MEAS] - e[E_PD_FILT])
    return pr_ok


@njit(cache=True)
def consistency(k, e, a, position) -> int:
    """The consistency monitor's verdict on this sample (adapt.monitor); the chamber filter's
    position noise follows the disagreement (adapt.disagree_noise)."""
    x, Q = a.x, a.Q
    flow = e[E_FLOWN + adapt.FL_ACTIVE] > 0.5
    offset = e[E_OFFS + adapt.OF_OPEN] > 0.5
    v = adapt.monitor(k[K_MON:K_MON + adapt.NMK], e[E_MON:E_MON + adapt.NMS], position, x[0],
                      int(e[E_CODE]), int(e[E_CODE]) == fd.DRIFT or flow or offset,
                      int(e[E_EDGE]))
    if k[K_CHAMBERS] > 0.5:
        adapt.disagree_noise(Q, x, int(k[K_IGM]), k[K_BDIS], k[K_MON:K_MON + adapt.NMK],
                             e[E_MON:E_MON + adapt.NMS], int(e[E_EDGE]), k[K_QX], k[K_QXD],
                             adapt.load_varying(e[E_OFFS:E_OFFS + adapt.NOFS], k[K_FLOWDP]),
                             k[K_QXO])
    return v


@njit(cache=True)
def estimate(k, e, a, position, w, pa, pb):
    """Estimator.update on a usable position sample (``w``: the speed it takes, the held one
    when the sample's is not valid; invalid pressures are left out): :func:`advance`, the
    update with position (and pressures), the adaptive parts, the fault detector and
    :func:`consistency`. Returns (position, innovation, nis, nis_dim, code)."""
    pr_ok = advance(k, e, a, w, pa, pb)
    x, P, Q, H, R, y, S, H1, R1, y1, S1, zm, z1, ws = (a.x, a.P, a.Q, a.H, a.R, a.y, a.S, a.H1,
                                                       a.R1, a.y1, a.S1, a.zm, a.z1, a.ws)
    use_p = k[K_USE_P] > 0.5
    iu = -1
    if k[K_CHAMBERS] > 0.5:
        iu = adapt.leakage_unexcited(x, int(k[K_ILAM]), k[K_PEXC])
    if k[K_NADAPT] > 0.5:
        noise_level.update(k[K_NL:K_NL + noise_level.NNK], e[E_NL:E_NL + noise_level.NNS],
                           position, pa, pb, pr_ok and use_p, w, R, R1, Q)
    if pr_ok and use_p:
        zm[0] = position
        if k[K_CHAMBERS] > 0.5:
            zm[1] = pa
            zm[2] = pb
        else:
            zm[1] = e[E_PD_MEAS]
        nis = update_gated(x, P, H, R, zm, y, S, ws, int(k[K_IFROZEN]), k[K_GATE], iu,
                           int(k[K_IMOVED]), k[K_MOVEDZ])
        innov, s00, m = y[0], S[0, 0], zm.shape[0]
        pz = fd.pressure_z(y, S, m)
    else:
        z1[0] = position
        nis = update_gated(x, P, H1, R1, z1, y1, S1, ws, int(k[K_IFROZEN]), k[K_GATE], iu,
                           -1, 0.0)
        innov, s00, m = y1[0], S1[0, 0], 1
        pz = 0.0
    if k[K_CHAMBERS] > 0.5:
        e[E_EDGE] = adapt.project(x, int(k[K_ILAM]), k[K_LAMLO], k[K_LAMHI], int(k[K_IDEL]),
                                  k[K_DELLO], k[K_DELHI], int(k[K_IKAP]), k[K_KAPLO],
                                  k[K_KAPHI], int(k[K_IPHI]), k[K_PHILO], k[K_PHIHI],
                                  int(k[K_IEPS]), k[K_EPSLO], k[K_EPSHI], int(k[K_IGM]),
                                  k[K_BMAX],
                                  e[E_CLIPPED:E_CLIPPED + 1], adapt.EDGE_TICKS)
    e[E_UPDATES] += 1
    fd.detect(k[K_FD:K_FD + fd.NFK], e[E_FD:E_FD + fd.NFS], position, innov, s00, pz)
    if k[K_CHAMBERS] > 0.5:
        adapt.maneuver(Q, int(k[K_ILOAD]), pz, k[K_LOADZ],
                       k[K_QLOAD] + e[E_FS + adapt.FS_Q], k[K_QLOADJ])
        b_sigma = k[K_BDIS] * e[E_NL + noise_level.NS_SX]
        of = e[E_OFFS:E_OFFS + adapt.NOFS]
        adapt.offset_noise(x, int(k[K_IGM]), b_sigma, of, k[K_OFFA], k[K_OFFA + 1],
                           k[K_OFFA + 2], k[K_OFFG], k[K_FLOWDP])
        rest = (k[K_STRIBECK] > 0.5 and e[E_FS + adapt.FS_N] >= k[K_FK + adapt.FK_NREST]
                and not adapt.load_varying(of, k[K_FLOWDP]))
        # at rest under a held load (beyond what friction holds): publish x_hat + b
        r = k[K_HOLDR] if rest and abs(x[2] - x[3]) > k[K_FLOWDP] else -k[K_HOLDR]
        e[E_HOLDW] = min(1.0, max(0.0, e[E_HOLDW] + r))
        adapt.flow_noise(
            Q, x, int(k[K_IFLOW]), int(k[K_IGM]), b_sigma, k[K_FLOWK], k[K_QFLOW], rest,
            e[E_FLOWN:E_FLOWN + adapt.NFLOW], k[K_FLOWN], k[K_FK:K_FK + adapt.NFK],
            k[K_FLOWDP], k[K_FLOWSH], k[K_FLOWREP])
    consistency(k, e, a, position)
    return published(e, x, int(k[K_IGM])), innov, nis, m, int(e[E_CODE])


@njit(cache=True)
def published(e, x, i_gm) -> float:
    """The position the estimate publishes: x_hat, and at rest under a held load (blended in
    and out) x_hat + b, the sensor's reading without its white noise."""
    if i_gm < 0:
        return x[0]
    return x[0] + e[E_HOLDW] * x[i_gm]
