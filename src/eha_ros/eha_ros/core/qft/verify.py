"""Verification beyond the design frequencies: for given (G_v, G, F) on every plant of the
family, closed-loop eigenvalues and every specification on a dense frequency grid, GM/PM,
closed-loop bandwidth, and the design-frequency bound check."""
from __future__ import annotations

import numpy as np

from . import bounds as qb
from .cost import drop_state
from .family import I_X, C_row, velocity_loop_plants, torque_responses
from .freqresp import feedback, max_real_eig
from .prefilter import band_grid, bandwidth


def margins(L, w):
    """(GM dB, PM deg) per row of L on grid w: GM = smallest -|L| dB where the unwrapped
    phase crosses -180 + k 360 with |L| < 1; PM = smallest 180 + phase at |L| = 1 crossings."""
    mag = qb.db(np.abs(L))
    ph = np.rad2deg(np.unwrap(np.angle(L), axis=1))
    gm = np.full(L.shape[0], np.inf)
    pm = np.full(L.shape[0], np.inf)
    for i in range(L.shape[0]):
        m, p = mag[i], ph[i]
        s = np.nonzero(np.sign(m[:-1]) != np.sign(m[1:]))[0]
        for j in s:
            t = m[j] / (m[j] - m[j + 1])
            pc = p[j] + t * (p[j + 1] - p[j])
            pm[i] = min(pm[i], (pc + 180.0) % 360.0 if (pc + 180.0) % 360.0 <= 180 else
                        (pc + 180.0) % 360.0 - 360.0)
        q = (p + 180.0) / 360.0
        k = np.nonzero(np.floor(q[:-1]) != np.floor(q[1:]))[0]
        for j in k:
            target = 360.0 * max(np.floor(q[j]), np.floor(q[j + 1])) - 180.0
            t = (target - p[j]) / (p[j + 1] - p[j])
            mc = m[j] + t * (m[j + 1] - m[j])
            if mc < 0:
                gm[i] = min(gm[i], -mc)
    return gm, pm


def analyse(fam, spec, Gv, G, F, vbounds=None, pbounds=None) -> dict:
    """All figures of the report for one controller set; values in SI/dB/deg/Hz."""
    r = {}
    wd = np.logspace(np.log10(spec['verify.w_min']), np.log10(spec['verify.w_max']),
                     spec['verify.n_points'])
    # velocity loop
    A, B, _ = fam.all_A()
    Cw = np.broadcast_to(C_row(1, A.shape[1]), A.shape[:2])
    Av = drop_state(feedback(A, B, Cw, Gv.ss())[0], I_X)
    r['vel_max_real_eig'] = float(max_real_eig(Av).max())
    Piw = torque_responses(fam, wd)[0]
    Lv = Piw * Gv.freq(wd)[None]
    r['vel_max_T_db'] = float(qb.db(np.abs(Lv / (1 + Lv)).max()))
    r['vel_Ws_db'] = float(qb.db(spec['velocity.Ws']))
    wv = wd <= max(spec['velocity.freqs'])
    Sv = np.abs(1 / (1 + Lv[:, wv])) / np.abs(spec.S_v(wd[wv]))[None]
    r['vel_sens_worst_db'] = float(qb.db(Sv.max()))
    gm, pm = margins(Lv, wd)
    r['vel_gm_min_db'], r['vel_pm_min_deg'] = float(gm.min()), float(pm.min())
    if vbounds is not None:
        L0 = torque_responses(fam, vbounds.w)[0][-1] * Gv.freq(vbounds.w)
        r['vel_bound_violation_db'] = float(qb.violation_db(vbounds.merged, L0).max())
    # position loop: each plant with its own closed velocity loop
    casc = velocity_loop_plants(fam, Gv)
    Cx = np.broadcast_to(casc.C_x, casc.A.shape[:2])
    Ap = feedback(casc.A, casc.B_ref, Cx, G.ss())[0]
    r['pos_max_real_eig'] = float(max_real_eig(Ap).max())
    Pw, Pd = casc.P_omega(wd), casc.P_d(wd)
    L = Pw * G.freq(wd)[None]
    T = L / (1 + L)
    S = 1 / (1 + L)
    r['pos_max_T_db'] = float(qb.db(np.abs(T).max()))
    r['pos_Ws_db'] = float(qb.db(spec['position.Ws']))
    band = wd <= 2 * np.pi * spec['verify.band_max_hz']
    r['pos_sens_worst_db'] = float(qb.db((np.abs(S[:, band]) / np.abs(spec.S_p(wd[band]))).max()))
    r['pos_stiff_worst_db'] = float(qb.db((np.abs(Pd[:, band] * S[:, band]) /
                                           np.abs(spec.M(wd[band]))).max()))
    r['pos_stiffness_min_N_per_mm'] = float(1e-3 / np.abs(Pd[:, band] * S[:, band]).max())
    gm, pm = margins(L, wd)
    r['pos_gm_min_db'], r['pos_pm_min_deg'] = float(gm.min()), float(pm.min())
    wt = band_grid(spec, 300)
    Lt = casc.P_omega(wt) * G.freq(wt)[None]
    FT = F.freq(wt)[None] * Lt / (1 + Lt)
    m = qb.db(np.abs(FT))
    r['track_over_up_db'] = float((m - qb.db(np.abs(spec.T_up(wt)))[None]).max())
    r['track_under_low_db'] = float((qb.db(np.abs(spec.T_low(wt)))[None] - m).max())
    r['track_tol_db'] = spec['position.track_tol_db']
    wb = np.logspace(-1, 4, 1500)
    Lb = casc.P_omega(wb) * G.freq(wb)[None]
    bw = bandwidth(F.freq(wb)[None] * Lb / (1 + Lb), wb) / (2 * np.pi)
    r['bw_min_hz'], r['bw_max_hz'], r['bw_nominal_hz'] = float(bw[:-1].min()), \
        float(bw[:-1].max()), float(bw[-1])
    if pbounds is not None:
        L0 = casc.P_omega(pbounds.w)[-1] * G.freq(pbounds.w)
        r['pos_bound_violation_db'] = float(qb.violation_db(pbounds.merged, L0).max())
        r['pos_bound_violation_by_w'] = [float(v) for v in qb.violation_db(pbounds.merged, L0)]
    # verdicts
    tol = 1e-6
    r['pass'] = {
        'vel_stable': r['vel_max_real_eig'] < 0,
        'vel_Ws': r['vel_max_T_db'] <= r['vel_Ws_db'] + tol,
        'vel_sensitivity': r['vel_sens_worst_db'] <= tol,
        'pos_stable': r['pos_max_real_eig'] < 0,
        'pos_Ws': r['pos_max_T_db'] <= r['pos_Ws_db'] + tol,
        'pos_sensitivity': r['pos_sens_worst_db'] <= tol,
        'pos_stiffness': r['pos_stiff_worst_db'] <= tol,
        'tracking': max(r['track_over_up_db'], r['track_under_low_db']) <= r['track_tol_db'],
        'bandwidth_nominal': r['bw_nominal_hz'] >= spec['prefilter.bandwidth_min_hz'],
    }
    if vbounds is not None:
        r['pass']['vel_bounds'] = r['vel_bound_violation_db'] <= tol
    if pbounds is not None:
        r['pass']['pos_bounds'] = r['pos_bound_violation_db'] <= tol
    r['all_pass'] = bool(all(r['pass'].values()))
    return r
