"""Verification beyond the design frequencies: for given (G_v, G, F) on every plant of the
family, closed-loop eigenvalues and every specification on a dense frequency grid, GM/PM,
closed-loop bandwidth, and the design-frequency bound check, all with the loop delay T_d;
then the DIGITAL loop: each closed velocity loop discretised with ZOH at Ts, the delay as
shift states (round(drive.delay/Ts) + 1 samples), G and F by Tustin (controller/discrete.py):
eigenvalues, nominal max|T|/GM/PM against the continuous-with-delay figures, and step
responses of F T (nominal and worst plant)."""
from __future__ import annotations

import numpy as np

from . import bounds as qb
from .cost import drop_state
from .family import I_X, C_row, velocity_loop_plants, torque_responses
from .freqresp import feedback, max_real_eig, pad
from .prefilter import band_grid, bandwidth, filtered_steps, step_metrics
from ..controller.discrete import freqresp_z, tustin


def zoh_batch(A, B, Ts):
    """ZOH discretisation of a batch (N, n, n), (N, n) by the matrix exponential."""
    from scipy.linalg import expm
    N, n, _ = A.shape
    M = np.zeros((N, n + 1, n + 1))
    M[:, :n, :n] = A * Ts
    M[:, :n, n] = B * Ts
    E = expm(M)
    return E[:, :n, :n], E[:, :n, n]


class DigitalLoop:
    """Discrete position loop of every plant (nominal last) at Ts: ZOH plant (closed velocity
    loop x/omega_ref), n_delay shift states on the command, Tustin G (shared discrete.py).

    States [x_plant, s_1..s_d, x_G]; s_1 <- u(k), plant input = s_d; e(k) = r(k) - x(k)."""

    def __init__(self, casc, Ts, n_delay, prewarp_w=0.0):
        self.Ts, self.nd, self.pw = Ts, int(n_delay), prewarp_w or None
        self.Phi, self.Gam = zoh_batch(casc.A, casc.B_ref, Ts)
        self.Cx = np.asarray(casc.C_x, float)

    def closed_loop(self, G):
        Ac, Bc, Cc, Dc = tustin(*G.ss(), self.Ts, self.pw)
        N, n, _ = self.Phi.shape
        d, m = self.nd, Ac.shape[0]
        k = n + d + m
        A = np.zeros((N, k, k))
        Br = np.zeros((N, k))
        A[:, :n, :n] = self.Phi
        A[:, :n, n + d - 1] = self.Gam
        A[:, n, :n] = -Dc[0, 0] * self.Cx
        A[:, n, n + d:] = Cc[0]
        Br[:, n] = Dc[0, 0]
        for j in range(1, d):
            A[:, n + j, n + j - 1] = 1.0
        A[:, n + d:, :n] = -Bc[:, 0:1][None] * self.Cx[None, None, :]
        A[:, n + d:, n + d:] = Ac
        Br[:, n + d:] = Bc[:, 0]
        return A, Br, pad(self.Cx, d + m)

    def max_abs_eig(self, G):
        return np.max(np.abs(np.linalg.eigvals(self.closed_loop(G)[0])), axis=-1)

    def loop_freq(self, G, w, idx=-1):
        """Open loop G(z) z^-d P_zoh(z) of plant idx at e^{j w Ts}."""
        z = np.exp(1j * np.asarray(w, float) * self.Ts)
        Gd = freqresp_z(*tustin(*G.ss(), self.Ts, self.pw), w, self.Ts)
        Phi, Gam = self.Phi[idx], self.Gam[idx]
        n = Phi.shape[0]
        P = np.array([self.Cx @ np.linalg.solve(zi * np.eye(n) - Phi, Gam) for zi in z])
        return Gd * z ** (-self.nd) * P

    def steps(self, G, horizon):
        """Unit-step responses x(k)/r of the closed loops, (N+1, K), k = 0..K-1."""
        A, Br, C = self.closed_loop(G)
        K = int(round(horizon / self.Ts)) + 1
        x = np.zeros(Br.shape)
        y = np.empty((A.shape[0], K))
        for k in range(K):
            y[:, k] = x @ C
            x = np.einsum('nij,nj->ni', A, x) + Br
        return y


def digital_loop(casc, spec, fam) -> DigitalLoop:
    return DigitalLoop(casc, spec['digital.Ts'], spec.delay_samples(fam.drive_delay),
                       spec['digital.prewarp_w'])


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


def dense_grid(spec) -> np.ndarray:
    """The verification grid: verify.n_points log-spaced over verify.w_min..w_max (rad/s)."""
    return np.logspace(np.log10(spec['verify.w_min']), np.log10(spec['verify.w_max']),
                       spec['verify.n_points'])


def family_worst(Pw, Pd, Gw) -> dict:
    """Per frequency, over the family (rows of P_omega, P_d): max|T|, min|T|, max|S| and
    max|P_d S| of the position loop L = P_omega G (eqs. 4.51, 4.57, 4.59, 4.61)."""
    L = Pw * Gw[None]
    S = 1 / (1 + L)
    T = np.abs(L * S)
    return {'T_max': T.max(0), 'T_min': T.min(0), 'S_max': np.abs(S).max(0),
            'PdS_max': np.abs(Pd * S).max(0)}


def analyse(fam, spec, Gv, G, F, vbounds=None, pbounds=None, aw_poles=None) -> dict:
    """All figures of the report for one controller set; values in SI/dB/deg/Hz. With the
    anti-windup poles: the circle criterion of the clamped loop on every plant (qft.antiwindup)."""
    r = {}
    wd = dense_grid(spec)
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
    T_d = spec.loop_delay(fam.drive_delay)
    r['loop_delay_ms'] = 1e3 * T_d
    casc = velocity_loop_plants(fam, Gv, T_d)
    Ae, Be, Cx = casc.delayed_ss()
    Ap = feedback(Ae, Be, Cx, G.ss())[0]
    r['pos_max_real_eig'] = float(max_real_eig(Ap).max())
    Pw = casc.P_omega(wd)
    L = Pw * G.freq(wd)[None]
    worst = family_worst(Pw, casc.P_d(wd), G.freq(wd))
    r['pos_max_T_db'] = float(qb.db(worst['T_max'].max()))
    r['pos_Ws_db'] = float(qb.db(spec['position.Ws']))
    band = wd <= 2 * np.pi * spec['verify.band_max_hz']
    r['pos_sens_worst_db'] = float(qb.db((worst['S_max'] / np.abs(spec.S_p(wd)))[band].max()))
    r['pos_stiff_worst_db'] = float(qb.db((worst['PdS_max'] / np.abs(spec.M(wd)))[band].max()))
    r['pos_stiffness_min_N_per_mm'] = float(1e-3 / worst['PdS_max'][band].max())
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
    # digital loop at Ts
    Ts = spec['digital.Ts']
    dl = digital_loop(casc, spec, fam)
    r['dig_Ts_ms'] = 1e3 * Ts
    r['dig_delay_samples'] = dl.nd
    r['dig_max_abs_eig'] = float(dl.max_abs_eig(G).max())
    wz = wd[wd < 0.95 * np.pi / Ts]
    Lc = casc.P_omega(wz)[-1:] * G.freq(wz)[None]
    Lz = dl.loop_freq(G, wz)[None]
    for tag, LL in (('cont', Lc), ('dig', Lz)):
        gmn, pmn = margins(LL, wz)
        r[f'nom_{tag}_max_T_db'] = float(qb.db(np.abs(LL / (1 + LL)).max()))
        r[f'nom_{tag}_gm_db'], r[f'nom_{tag}_pm_deg'] = float(gmn[0]), float(pmn[0])
    r['dig_dT_db'] = abs(r['nom_dig_max_T_db'] - r['nom_cont_max_T_db'])
    r['dig_dGM_db'] = abs(r['nom_dig_gm_db'] - r['nom_cont_gm_db']) \
        if np.isfinite(r['nom_dig_gm_db']) or np.isfinite(r['nom_cont_gm_db']) else 0.0
    r['dig_dPM_deg'] = abs(r['nom_dig_pm_deg'] - r['nom_cont_pm_deg'])
    yT = dl.steps(G, spec['digital.horizon'])
    y = filtered_steps(F, yT, Ts, spec['digital.prewarp_w'])
    os_pct, ts = step_metrics(y, Ts, spec['digital.settling_band'])
    r['step_mm'] = 1e3 * spec['digital.step']
    r['step_overshoot_pct'], r['step_settling_s'] = float(os_pct[-1]), float(ts[-1])
    r['step_overshoot_worst_pct'] = float(os_pct[:-1].max())
    r['step_settling_worst_s'] = float(ts[:-1].max())
    r['step_worst_plant'] = int(np.argmax(ts[:-1]))
    r['step_nominal_t'] = np.arange(y.shape[1]) * Ts
    r['step_nominal_y'] = spec['digital.step'] * y[-1]
    if aw_poles is not None:
        from .antiwindup import circle_figures
        r.update(circle_figures(G, aw_poles, dl, wd))
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
        'dig_stable': r['dig_max_abs_eig'] < 1.0,
        'dig_agree': r['dig_dT_db'] <= spec['digital.agree_db'] and
        r['dig_dGM_db'] <= spec['digital.agree_db'] and r['dig_dPM_deg'] <= spec['digital.agree_deg'],
        'step_nominal': r['step_overshoot_pct'] <= spec['digital.overshoot_max_pct'] and
        r['step_settling_s'] <= spec['digital.settling_max'],
        'step_family': r['step_overshoot_worst_pct'] <= spec['digital.overshoot_max_pct'] and
        r['step_settling_worst_s'] <= spec['digital.settling_max'],
    }
    if vbounds is not None:
        r['pass']['vel_bounds'] = r['vel_bound_violation_db'] <= tol
    if pbounds is not None:
        r['pass']['pos_bounds'] = r['pos_bound_violation_db'] <= tol
    if aw_poles is not None:
        # Re H >= 0 (to rounding: H -> 0 at w -> 0 by the plant's integrator)
        r['pass']['aw_circle'] = r['aw_circle_min_re'] >= -tol
    r['all_pass'] = bool(all(r['pass'].values()))
    return r
