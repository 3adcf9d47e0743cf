"""Linear predictions of the campaign loop, one per plant variant (core.qft models).

The loop of core.sim.scenarios, linearised: each variant's torque-mode plant (eq. 3.35,
qft.family) under its own closed velocity loop G_v (the drive gains plant.drive.Kp_w, Ki_w,
lowpass_w of eq. 4.65), the position controller G and prefilter F of the controller YAML,
and the loop delay T_d = 1.5 Ts + plant.drive.delay on the speed reference (as in
scripts/design_qft). The position is fed back without error (no estimator), friction is the
viscous b of eq. 3.23 only, and the controller's leakage compensation, which supplies the
estimator's leak flow, is not part of it: these are the QFT loop's figures. ``cascade``'s
``leak_gain`` closes a fixed compensation omega_ref += K_c p_D through the same delay
(qft.family.CascadePlants), for the compensation's stability over the family.

- tracking x/r = F P G/(1 + P G) with P = P_omega e^{-s T_d}: gain (dB) and phase (deg,
  wrapped to (-180, 180] as core.sweep.analysis.sine_point reports it) per frequency;
- dynamic stiffness |F_L|/|x| = 1/|P_d S| (kN/mm, thesis Fig. 4.52);
- the load step: x(t) of P_d S (continuous time, delay as a Pade cascade), its peak |x| and
  the steady error |mean x| over the window the load_step scenario uses.

The drive divides the speed PI by the plant's OWN k_T (core.plant.drive.speed_pi reads the
variant's k_T), so by default G_v here does too (``drive_kT='plant'``); the QFT design keeps
G_v's 1/k_T at the nominal value for every plant (``drive_kT='nominal'`` reproduces the
figures of scripts/design_qft exactly).
"""
from __future__ import annotations

import os

import numpy as np

from ..qft import family as qf
from ..qft.freqresp import feedback, pad
from ..qft.spec import configured_spec
from ..controller.lti import Zpk, from_num_den, velocity_controller

NAMES = qf.NAMES
FREQS_HZ = (1, 2, 4, 7, 10, 15)
STIFF_FREQS_HZ = (1, 4, 7)


# ------------------------------------------------------------------------------ inputs
def default_plant(config_dir: str | None = None) -> dict:
    """config/plant.yaml validated against the plant schema (dotted keys)."""
    from ..config.params import default_config_dir, load
    from ..plant.parameters import PLANT_SCHEMA
    return load(PLANT_SCHEMA, [os.path.join(config_dir or default_config_dir(), 'plant.yaml')])


def default_controller(config_dir: str | None = None) -> dict:
    """The controller node's parameters (plant.yaml, controller.yaml, controller_node.yaml)."""
    from .batch import node_params
    from ..controller.params import SCHEMA
    return node_params('controller', SCHEMA, config_dir)


def controllers(plant: dict, controller: dict) -> tuple[Zpk, Zpk, Zpk]:
    """(G_v, G, F): G_v from the drive gains of ``plant`` (eq. 4.65 with the nominal k_T),
    G and F from the controller parameters (position_controller/prefilter .num/.den)."""
    Gv = velocity_controller(plant['plant.drive.Kp_w'], plant['plant.drive.Ki_w'],
                             plant['plant.drive.lowpass_w'], plant['plant.motor.k_T'])
    G = from_num_den(controller['position_controller.num'], controller['position_controller.den'])
    F = from_num_den(controller['prefilter.num'], controller['prefilter.den'])
    return Gv, G, F


def loop_delay(plant: dict, spec=None) -> float:
    """T_d [s]: spec digital.delay when set (>= 0), else 1.5 Ts + plant.drive.delay with Ts
    the plant's tick (plant.sim.Ts), as qft.spec.QftSpec.loop_delay derives it."""
    if spec is not None and spec['digital.delay'] >= 0:
        return float(spec['digital.delay'])
    return 1.5 * float(plant['plant.sim.Ts']) + float(plant['plant.drive.delay'])


def _fhz(f) -> str:
    """Column suffix of a frequency, as core.sim.scenarios names the nonlinear figures."""
    f = float(f)
    return f'{int(f)}' if f.is_integer() else f'{f:g}'.replace('.', 'p')


# ------------------------------------------------------------------------------ operating point
def operating_leakage(plant: dict, load: float) -> float:
    """C_eq [m^3/(s Pa)] of the loop holding a constant load F_L: eq. 3.22's C_p + C_c + C_r/2
    while both chambers stay above the boost check valves, C_p + C_c + C_r once the load puts
    the unloaded chamber on its check valve (Fig. 3.12).

    Held (v = 0) with p_A - p_B = dp = |F_L|/A_p, the two chambers' flow balances (eq. 3.15)
    add up to C_r (p_A + p_B - 2 p_acc) = q_check: without a check-valve flow the pair is
    symmetric about the accumulator, p_B = p_acc - dp/2. Once dp/2 exceeds the cracking
    pressure the valve holds p_B at p_acc - crack, p_A = p_B + dp, and the pump covers
    D_p omega = (C_p + C_c) dp + C_r (p_A - p_acc) = (C_p + C_c + C_r) dp - C_r crack: the loaded
    chamber loses its whole external leakage. The eta_v map of eq. 3.31 is not modelled here
    (the linear family of eq. 3.35 uses C_p, C_c, C_r)."""
    from ..plant.parameters import PlantParams
    p = PlantParams.from_dict(plant)
    if abs(load) / p.A_p / 2.0 > plant['plant.valves.check_crack']:
        return p.C_p + p.C_c + p.C_r
    return p.C_eq


def loaded_C_eq(base: dict, rows: dict, load: float) -> np.ndarray:
    """Multipliers of ``base``'s C_eq (eq. 3.22) at the operating point of each plant of
    ``rows`` (core.sim.family columns, a missing one nominal) holding ``load`` N
    (operating_leakage)."""
    from ..plant.parameters import PlantParams
    from .family import COLUMNS, plant_params
    n = len(rows['C_eq'])
    c0 = PlantParams.from_dict(base).C_eq
    return np.array([operating_leakage(plant_params(
        base, {c: float(rows[c][i]) if c in rows else 1.0 for c in COLUMNS}), load)
        for i in range(n)]) / c0


# ------------------------------------------------------------------------------ models
def cascade(scales, plant: dict, Gv: Zpk, delay: float, drive_kT: str = 'plant',
            leak_gain: float = 0.0):
    """qft.family.CascadePlants of the variants (rows of ``scales``, nominal plant.yaml
    appended last): each torque-mode plant under its own closed velocity loop G_v, with a fixed
    leakage compensation omega_ref += ``leak_gain`` p_D (rad/s per Pa; 0: none).

    drive_kT='plant': the drive's 1/k_T follows the variant (as the nonlinear drive);
    'nominal': G_v's 1/k_T stays nominal (the QFT design's family)."""
    scales = np.atleast_2d(np.asarray(scales, float))
    if scales.shape[1] != len(NAMES):
        raise ValueError(f'scales: expected (N, {len(NAMES)}) multipliers {NAMES}, '
                         f'got shape {scales.shape}')
    if drive_kT not in ('plant', 'nominal'):
        raise ValueError(f"drive_kT={drive_kT!r}: expected 'plant' or 'nominal'")
    uniq, inv = np.unique(scales, axis=0, return_inverse=True)
    mats = [qf._abcd(qf.scaled_params(plant, s)) for s in uniq]
    A = np.array([m[0] for m in mats])
    B = np.array([m[1] for m in mats])
    BL = np.array([m[2] for m in mats])
    if drive_kT == 'plant':
        # i_ref = G_v(k_T of the variant) e = (k_T0/k_T) G_v(k_T0) e: fold the ratio into B
        B = B / uniq[:, 3:4]
    A0, B0, BL0 = qf._abcd(plant)
    p0 = plant
    fam = qf.TorqueFamily(uniq, A, B, BL, A0, B0, BL0, float(p0['plant.motor.k_T']),
                          p0['plant.pump.D_p'] / p0['plant.cylinder.A_p'],
                          float(p0['plant.drive.delay']))
    casc = qf.velocity_loop_plants(fam, Gv, delay, leak_gain)
    return casc, np.asarray(inv).reshape(-1)


def closed_loop_load(casc, G: Zpk, order: int = 4):
    """(A, B_load, C_x) of x/F_L in the closed position loop, every plant of ``casc``: the
    delay as a Pade cascade of ``order`` at the speed-reference input, G in feedback."""
    Ae, Be, Ce = casc.delayed_ss(order)
    m = Ae.shape[1] - casc.A.shape[1]
    Bl = pad(casc.B_load, m)
    Acl, _, (Blc,) = feedback(Ae, Be, Ce, G.ss(), extra_B=(Bl,))
    return Acl, Blc, pad(np.asarray(Ce, float), Acl.shape[1] - Ae.shape[1])


def _mm(X, Y):
    """Batched matrix product without BLAS: OpenBLAS threads on thousands of tiny products
    stall on a busy machine (seconds instead of milliseconds)."""
    return np.einsum('nij,njk->nik', X, Y)


def expm_batch(X, order: int = 12) -> np.ndarray:
    """e^X of a batch (N, m, m) of BALANCED matrices: Taylor series of ``order`` after scaling
    to norm <= 0.5, then squaring (truncation error < 1e-14 relative)."""
    X = np.asarray(X, float)
    nrm = np.abs(X).sum(axis=1).max() if X.size else 0.0
    s = int(max(0, np.ceil(np.log2(nrm / 0.5)))) if nrm > 0 else 0
    Y = X / 2.0 ** s
    eye = np.broadcast_to(np.eye(X.shape[1]), X.shape)
    E = eye + Y / order
    for k in range(order - 1, 0, -1):          # Horner: I + Y/1 (I + Y/2 (... (I + Y/order)))
        E = eye + _mm(Y, E) / k
    for _ in range(s):
        E = _mm(E, E)
    return E


def _power(E, k: int) -> np.ndarray:
    """E^k of a batch by repeated squaring (einsum products)."""
    out = np.broadcast_to(np.eye(E.shape[1]), E.shape).copy()
    base = E
    while k:
        if k & 1:
            out = _mm(out, base)
        k >>= 1
        if k:
            base = _mm(base, base)
    return out


def _orbit(E, z0, C, K: int, block: int = 64):
    """Outputs y_k = C E^k z0, k = 0..K, of a batch E (N, m, m), z0 (N, m), C (N, m):
    ``block`` sequential steps, then whole blocks at once (E^block times the previous block;
    only one block of states is held). Returns (y (N, K + 1), z_K (N, m))."""
    N, m, _ = E.shape
    b = max(1, min(block, K + 1))
    Z = np.empty((N, b, m))
    Z[:, 0] = z0
    for k in range(1, b):
        Z[:, k] = np.einsum('nij,nj->ni', E, Z[:, k - 1])
    y = np.empty((N, K + 1))
    y[:, :b] = np.einsum('nkj,nj->nk', Z, C)
    Eb = _power(E, b)
    k = b
    while k <= K:
        Z = np.einsum('nkj,nij->nki', Z, Eb)
        j = min(b, K + 1 - k)
        y[:, k:k + j] = np.einsum('nkj,nj->nk', Z[:, :j], C)
        last = Z[:, j - 1]
        k += j
    return y, (Z[:, K] if K < b else last)


def step_response(A, B, C, dt: float = 1e-4, t_fine: float = 0.5, coarse: int = 20,
                  horizon: float = 4.5):
    """Unit-step responses y(t) of a batch (N, n, n), (N, n), (N, n): exact for the held
    input (matrix exponential of [[A, B], [0, 0]] dt); step dt up to t_fine, coarse x dt
    after it up to horizon. Returns (t (K,), y (N, K))."""
    from scipy.linalg import matrix_balance
    N, n, _ = A.shape
    M = np.zeros((N, n + 1, n + 1))
    M[:, :n, :n] = A
    M[:, :n, n] = B
    # balance first: rows of eq. 3.35 span ~1e-2..1e10 (2 beta A_p/V_d), and an unbalanced
    # exponential leaves an O(eps |M|) error in Phi that the long sum turns into a drift
    Cz = np.zeros((N, n + 1))
    Cz[:, :n] = C
    z0 = np.zeros((N, n + 1))
    z0[:, n] = 1.0
    for i in range(N):
        _, (sc, _) = matrix_balance(M[i], permute=False, separate=True)
        M[i] = M[i] * sc[None, :] / sc[:, None]          # T^-1 M T, T = diag(sc)
        Cz[i] = Cz[i] * sc
        z0[i] = z0[i] / sc
    E = expm_batch(M * dt)
    k1 = int(round(min(t_fine, horizon) / dt))
    y1, z1 = _orbit(E, z0, Cz, k1)
    t, y = [np.arange(k1 + 1) * dt], [y1]
    k2 = int(round((horizon - k1 * dt) / (coarse * dt)))
    if k2 > 0:
        y2, _ = _orbit(_power(E, coarse), z1, Cz, k2)
        t.append(k1 * dt + np.arange(1, k2 + 1) * coarse * dt)
        y.append(y2[:, 1:])
    return np.concatenate(t), np.concatenate(y, axis=1)


def load_step_figures(t, x, steady=(3.5, 4.5)) -> tuple[np.ndarray, np.ndarray]:
    """(peak |x|, |mean x| over the steady window) per row of x (N, K) on t (K,)."""
    win = (t >= steady[0] - 1e-9) & (t <= steady[1] + 1e-9)
    return np.max(np.abs(x), axis=1), np.abs(np.mean(x[:, win], axis=1))


# ------------------------------------------------------------------------------ API
def predict(scales, freqs_hz=FREQS_HZ, stiff_freqs_hz=STIFF_FREQS_HZ, load_step_n=5e3,
            plant: dict | None = None, controller: dict | None = None, *,
            steady=(3.5, 4.5), horizon: float = 4.5, drive_kT: str = 'plant',
            spec=None, load_step: bool = True) -> dict[str, np.ndarray]:
    """Linear predictions of the campaign loop for each row of ``scales`` ((N, 5) Table 4.5
    multipliers [C_eq, D_p, beta, k_T, k_E]); arrays of N:

    ``lin_gain_db_<f>hz``, ``lin_phase_deg_<f>hz``: truth/reference = F P G/(1 + P G), the
    delay included (f as int when whole, e.g. lin_gain_db_7hz; phase wrapped to (-180, 180]);
    ``lin_stiffness_kn_per_mm_<f>hz``: |F_L|/|x| = 1/|P_d S| in kN/mm;
    ``lin_peak_deviation_m``: peak |x| after a ``load_step_n`` N load step (position fed back
    without error; continuous time, delay as Pade, over ``horizon`` s);
    ``lin_steady_error_m``: |mean x| over ``steady`` (s after the step).
    plant/controller: dotted parameter dicts (default: config/plant.yaml, the controller
    node's files); spec: a QftSpec for digital.delay (default: the plant's 1.5 Ts + drive
    delay); drive_kT: see the module doc."""
    plant = default_plant() if plant is None else plant
    controller = default_controller() if controller is None else controller
    Gv, G, F = controllers(plant, controller)
    casc, inv = cascade(scales, plant, Gv, loop_delay(plant, spec), drive_kT)
    out: dict[str, np.ndarray] = {}
    fr = np.asarray(list(freqs_hz), float)
    if len(fr):
        w = 2 * np.pi * fr
        L = casc.P_omega(w)[:-1] * G.freq(w)[None]
        H = F.freq(w)[None] * L / (1 + L)
        for j, f in enumerate(fr):
            out[f'lin_gain_db_{_fhz(f)}hz'] = 20 * np.log10(np.abs(H[inv, j]))
            out[f'lin_phase_deg_{_fhz(f)}hz'] = np.degrees(np.angle(H[inv, j]))
    fs = np.asarray(list(stiff_freqs_hz), float)
    if len(fs):
        w = 2 * np.pi * fs
        S = 1 / (1 + casc.P_omega(w)[:-1] * G.freq(w)[None])
        K = 1.0 / np.abs(casc.P_d(w)[:-1] * S) / 1e6          # N/m -> kN/mm
        for j, f in enumerate(fs):
            out[f'lin_stiffness_kn_per_mm_{_fhz(f)}hz'] = K[inv, j]
    if load_step:
        A, B, C = closed_loop_load(casc, G)
        t, y = step_response(A[:-1], B[:-1], C[:-1], horizon=horizon)
        peak, steady_err = load_step_figures(t, load_step_n * y, steady)
        out['lin_peak_deviation_m'] = peak[inv]
        out['lin_steady_error_m'] = steady_err[inv]
    return out


def stiffness_curve(scales, w, plant: dict | None = None, controller: dict | None = None,
                    drive_kT: str = 'plant', spec=None) -> np.ndarray:
    """|F_L|/|x| in kN/mm of each variant on the angular frequencies w (rad/s), (N, F)."""
    plant = default_plant() if plant is None else plant
    controller = default_controller() if controller is None else controller
    Gv, G, _ = controllers(plant, controller)
    casc, inv = cascade(scales, plant, Gv, loop_delay(plant, spec), drive_kT)
    w = np.atleast_1d(np.asarray(w, float))
    S = 1 / (1 + casc.P_omega(w)[:-1] * G.freq(w)[None])
    return (1.0 / np.abs(casc.P_d(w)[:-1] * S) / 1e6)[inv]


def bounds(spec=None, t=None, w=None) -> dict:
    """Spec bounds for plots (thesis 4.3.2).

    t (s, default 0..0.4 s): unit-step responses of T_up (eq. 4.62) and T_low (eq. 4.63),
    'T_up_step', 'T_low_step', and the envelope 'step_upper'/'step_lower' (their max/min: the
    bounds order |T| in frequency, |T_up| >= |T_low|, but T_up's step rings 0.25 % below
    T_low's near 0.16 s); w (rad/s, default 0.1..3000): |M(j w)| in m/N (eq. 4.60) as
    'M_m_per_N', the stiffness bound 1/|M| in kN/mm 'stiffness_bound_kn_per_mm', |T_up|,
    |T_low| in dB, and 'f_hz' = w/2 pi."""
    from scipy import signal
    spec = configured_spec() if spec is None else spec
    t = np.linspace(0.0, 0.4, 801) if t is None else np.asarray(t, float)
    w = np.logspace(-1, np.log10(3000.0), 400) if w is None else np.asarray(w, float)
    a, z = spec['position.a_up'], spec['position.zeta_up']
    wn = spec['position.wn_factor'] * a / z
    up = signal.lti([1.0 / a, 1.0], [1.0 / wn ** 2, 2 * z / wn, 1.0])
    p = spec['position.low_pole']
    low = signal.lti([1.0], [1.0 / p ** 2, 2.0 / p, 1.0])
    t0 = t - t[0]
    _, y_up = signal.step(up, T=t0)
    _, y_low = signal.step(low, T=t0)
    M = np.abs(spec.M(w))
    y_up, y_low = np.asarray(y_up), np.asarray(y_low)
    return {'t': t, 'T_up_step': y_up, 'T_low_step': y_low,
            'step_upper': np.maximum(y_up, y_low), 'step_lower': np.minimum(y_up, y_low),
            'w': w, 'f_hz': w / (2 * np.pi), 'M_m_per_N': M,
            'stiffness_bound_kn_per_mm': 1.0 / M / 1e6,
            'T_up_db': 20 * np.log10(np.abs(spec.T_up(w))),
            'T_low_db': 20 * np.log10(np.abs(spec.T_low(w)))}
