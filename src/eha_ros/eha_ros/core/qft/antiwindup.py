"""Anti-windup design and check for a position controller G (core.controller.antiwindup):

- circle criterion on every plant of the family: Re H(e^{j w Ts}) >= 0 with the digital loop
  (ZOH plant, loop delay, Tustin G) on the verification grid;
- saturation figures on the nonlinear nominal plant (core.plant.EhaPlant, the stack's
  PositionController): a 40 mm step with the reference rate and acceleration limits lifted,
  the piston held for 1 s with a 2 mm error then released, a 2 mm jump of the reference;
- the design: the poles of G while clamped (one per state) minimising the worst overshoot of
  those runs plus their 2 % settling times, with Re H >= 0 as a constraint (differential
  evolution over a box around G's corner frequencies, then Nelder-Mead).
"""
from __future__ import annotations

import numpy as np
from scipy import optimize

from ..controller.antiwindup import circle_h, observer_gain
from ..controller.discrete import tustin

# saturation runs: (name, step [m], rate limit [m/s], held ticks, ticks)
RUNS = (('step_40mm', 0.04, 5.0, 0, 1200), ('held_release', 0.002, 0.19, 1000, 1800),
        ('jump_2mm', 0.002, 5.0, 0, 800))


def plants_z(dl, w) -> np.ndarray:
    """Digital plants z^-d C (zI - Phi)^-1 Gam of the family (rows, nominal last) at w."""
    z = np.exp(1j * np.asarray(w, float) * dl.Ts)
    N, n, _ = dl.Phi.shape
    I = np.eye(n)
    out = np.empty((N, len(z)), complex)
    for i in range(N):
        X = np.linalg.solve(z[:, None, None] * I[None] - dl.Phi[i][None],
                            np.broadcast_to(dl.Gam[i], (len(z), n))[..., None])[..., 0]
        out[i] = (X @ dl.Cx) * z ** (-dl.nd)
    return out


def circle_grid(dl, w):
    """(w below Nyquist, the family's digital plants there) for circle_figures."""
    w = np.asarray(w, float)
    w = w[w < 0.999 * np.pi / dl.Ts]
    return w, plants_z(dl, w)


def circle_figures(G, poles, dl, w, Pz=None) -> dict:
    """min Re H over the family and the grid (w < pi/Ts) and where it is; Pz: plants_z at w
    (circle_grid) if already computed."""
    Ad, Bd, Cd, Dd = tustin(*G.ss(), dl.Ts, dl.pw)
    L = observer_gain(Ad, Cd, poles, dl.Ts)
    if Pz is None:
        w, Pz = circle_grid(dl, w)
    H = circle_h(Ad, Bd, Cd, Dd, L, Pz, np.exp(1j * w * dl.Ts))
    i, j = np.unravel_index(np.argmin(H.real), H.shape)
    return {'aw_circle_min_re': float(H.real[i, j]), 'aw_circle_worst_plant': int(i),
            'aw_circle_worst_w': float(w[j])}


def saturation_figures(G, F, poles, params: dict, drive_limit: bool = True) -> dict:
    """Overshoot (%), 2 % settling (s) and tail (m: mean |error| over the run's last 0.2 s:
    what a saturation leaves in G's slow mode, its integrator's zero at 0.5 rad/s) of RUNS on
    the nonlinear plant of ``params`` with the stack's controller (G, F as (num, den); poles
    None: no anti-windup; drive_limit: its actuator bounded by the drive's reach beyond the
    measured motor speed, as the stack runs it); the unclamped output's range while held."""
    from ..controller.position import PositionController, drive_reach_of
    from ..plant import EhaPlant
    out = {}
    reach = drive_reach_of(params) if drive_limit else 0.0
    for name, amp, rate, held, n in RUNS:
        ctl = PositionController(G, F, params['plant.sim.Ts'], params['plant.drive.omega_max'],
                                 params['plant.cylinder.stroke'], 0.005, rate,
                                 antiwindup=poles is not None, aw_poles=poles,
                                 drive_reach=reach)
        plant = EhaPlant(params, seed=1)
        ctl.start(0.0)
        ctl.request(amp)
        x = np.empty(n)
        u = np.empty(n)
        sat = np.empty(n)
        for k in range(n):
            o = ctl.update(0.0 if k < held else plant.truth().position,
                           plant.measure().motor_speed[0])
            u[k], sat[k] = o.unsaturated, o.speed_ref
            if k >= held:
                plant.step(o.speed_ref, 0.0)
            x[k] = plant.truth().position
        after = x[held:]
        bad = np.nonzero(np.abs(after - amp) > 0.02 * amp)[0]
        out[f'{name}_overshoot_pct'] = float(100 * max(0.0, after.max() - amp) / amp)
        out[f'{name}_settling_s'] = float((bad[-1] + 1) * params['plant.sim.Ts']) if bad.size else 0.0
        out[f'{name}_tail_m'] = float(np.mean(np.abs(after[-200:] - amp)))
        if held:
            # from 30 ms on (the shaped 2 mm reference is in)
            m = slice(30, held)
            out['held_u_min'], out['held_u_max'] = float(u[m].min()), float(u[m].max())
            out['held_clamped_same_sign'] = bool(np.all(sat[m] == params['plant.drive.omega_max']))
    return out


def n_pairs(n: int) -> int:
    """Complex pairs among n design poles: all but one real pole (odd n) or two (even n)."""
    return (n - 1) // 2 if n % 2 else (n - 2) // 2


def pole_vector(x, n: int) -> np.ndarray:
    """Poles from the design vector: n_r real (log10 |s|) then pairs (log10 w_n, zeta)."""
    n_real = n - 2 * n_pairs(n)
    p = [-10.0 ** v for v in x[:n_real]]
    for i in range(n_pairs(n)):
        wn, z = 10.0 ** x[n_real + 2 * i], float(np.clip(x[n_real + 2 * i + 1], 0.05, 0.995))
        p += [wn * complex(-z, np.sqrt(1 - z * z)), wn * complex(-z, -np.sqrt(1 - z * z))]
    return np.array(p)


def vector_from_poles(poles) -> np.ndarray:
    """Inverse of pole_vector (real poles first, then one entry pair per conjugate pair)."""
    p = np.asarray(poles, complex)
    real = [np.log10(-v.real) for v in p if abs(v.imag) < 1e-9]
    pairs = [v for v in p if v.imag > 1e-9]
    return np.array(real + [u for v in pairs for u in (np.log10(abs(v)), -v.real / abs(v))])


def box(G, n: int):
    """Design-vector bounds: real poles and pair frequencies from a tenth of G's slowest zero to
    pi/Ts-ish (3000 rad/s), damping 0.1-0.99."""
    slow = min([abs(z) for z in G.zeros if abs(z) > 1e-9] or [1.0])
    m = n_pairs(n)
    lo = [np.log10(0.1 * slow)] * (n - 2 * m) + [np.log10(slow), 0.1] * m
    hi = [np.log10(3000.0)] * (n - 2 * m) + [np.log10(3000.0), 0.99] * m
    return list(zip(lo, hi))


def design(G, F, dl, w, params: dict, seed: int = 0, maxiter: int = 15, maxfev: int = 150,
           start=None, progress=None):
    """(poles, figures): the poles minimising the worst overshoot of RUNS (+ settling, tails) with
    Re H >= 0 on the family and the output at the clamp of the error's sign while held
    (penalised); G a controller.lti.Zpk, F as (num, den). Differential evolution over box(), then
    Nelder-Mead from the better of its best and ``start`` (poles, e.g. the YAML's own)."""
    n = len(G.poles)
    num_den = G.num_den()
    best = {'cost': np.inf}
    w, Pz = circle_grid(dl, w)

    def cost(x):
        p = pole_vector(x, n)
        try:
            c = circle_figures(G, p, dl, w, Pz)['aw_circle_min_re']
            f = saturation_figures(num_den, F, p, params)
        except (ValueError, np.linalg.LinAlgError):
            return 1e3
        val = 1e4 * max(0.0, -c) + 0.1 * max(f[f'{r[0]}_overshoot_pct'] for r in RUNS) + \
            sum(f[f'{r[0]}_settling_s'] for r in RUNS[:2]) + \
            sum(f[f'{r[0]}_tail_m'] for r in RUNS) / 1e-4 + \
            10.0 * (not f['held_clamped_same_sign'])       # 100 um of tail weigh as 1 s
        if val < best['cost']:
            best.update(cost=val, x=x.copy())
        if progress:
            progress(best['cost'])
        return val

    if start is not None and len(start) == n:
        cost(vector_from_poles(start))
    if maxiter:
        optimize.differential_evolution(cost, box(G, n), seed=seed, maxiter=maxiter, popsize=8,
                                        polish=False, init='sobol')
    optimize.minimize(cost, best['x'], method='Nelder-Mead',
                      options=dict(maxfev=maxfev, xatol=1e-3, fatol=1e-4))
    p = pole_vector(best['x'], n)
    figs = circle_figures(G, p, dl, w, Pz)
    figs.update(saturation_figures(num_den, F, p, params))
    return p, figs
