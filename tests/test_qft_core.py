"""QFT toolchain core: family, state-space frequency responses, bounds vs brute force, PSO."""
import numpy as np
import pytest

from eha_ros.core.config.params import load
from eha_ros.core.plant import linear
from eha_ros.core.plant.parameters import PLANT_SCHEMA
from eha_ros.core.qft import bounds as qb
from eha_ros.core.config.params import ParamError
from eha_ros.core.controller import lti
from eha_ros.core.qft import cost, family, freqresp, minimax, prefilter, pso, verify
from eha_ros.core.qft.spec import QftSpec, default_spec, load_spec


@pytest.fixture(scope='module')
def setup():
    plant = load(PLANT_SCHEMA, ['config/plant.yaml'])
    spec = default_spec()
    fam = family.build_family(plant, spec)
    casc = family.velocity_loop_plants(fam, lti.thesis_velocity(fam.k_T_nominal))
    return plant, spec, fam, casc


def test_family_size_and_grid(setup):
    plant, spec, fam, _ = setup
    assert fam.n == 270
    s = fam.scales
    assert np.allclose(np.unique(s[:, 0]), np.geomspace(0.1, 10, 5))
    assert np.allclose(np.unique(s[:, 1]), [0.8, 1.0])
    assert np.allclose(np.unique(s[:, 2]), np.geomspace(0.7, 1.4, 3))
    # one sampled member equals linear.torque_abcd of the scaled parameter dict
    i = 137
    A, B, _, _ = linear.torque_abcd(family.scaled_params(plant, s[i]))
    assert np.allclose(fam.A[i], A) and np.allclose(fam.B[i], B[:, 0])
    assert np.allclose(fam.A0, linear.torque_abcd(plant)[0])


def test_cascade_matches_linear_velocity_model(setup):
    """Nominal closed velocity loop with the drive's G_v (plant.drive gains, eq. 4.65) equals
    linear.velocity_abcd(lowpass) of the same plant file."""
    plant, _, fam, _ = setup
    Gv = lti.velocity_controller(plant['plant.drive.Kp_w'], plant['plant.drive.Ki_w'],
                                 plant['plant.drive.lowpass_w'], fam.k_T_nominal)
    casc = family.velocity_loop_plants(fam, Gv)
    w = np.logspace(-2, 4, 40)
    abcd = linear.velocity_abcd(plant, lowpass=True)
    assert np.allclose(casc.P_omega(w)[-1], linear.freqresp(abcd, w, 0, 0), rtol=1e-9)
    assert np.allclose(casc.P_d(w)[-1], linear.freqresp(abcd, w, 1, 0), rtol=1e-9)


def test_state_space_response_vs_direct_and_ss2tf(setup):
    """Batched SS evaluation == direct per-frequency solve and ZPK; ss2tf (no slycot) is worse."""
    import control
    _, _, _, casc = setup
    G = lti.thesis_position()
    Cx = np.broadcast_to(casc.C_x, casc.A.shape[:2])
    A, Br, _ = freqresp.feedback(casc.A, casc.B_ref, Cx, G.ss())
    C = freqresp.pad(casc.C_x, 4)
    w = np.logspace(-2, 4, 80)
    H = freqresp.ss_freqresp(A[[0, 100, -1]], Br[[0, 100, -1]], C, w)
    for k, i in enumerate([0, 100, -1]):
        abcd = (A[i], Br[i][:, None], C[None], np.zeros((1, 1)))
        direct = linear.freqresp(abcd, w)
        assert np.max(np.abs(H[k] / direct - 1)) < 1e-10
        z, p, g = linear.zpk(abcd)
        hz = g * np.prod(1j * w[:, None] - z, 1) / np.prod(1j * w[:, None] - p, 1)
        assert np.max(np.abs(H[k] / hz - 1)) < 1e-6
    # x/F_L (order 8): ss2tf polynomial evaluation loses digits the state space keeps
    i = 0
    direct = linear.freqresp((casc.A[i], casc.B_load[i][:, None], casc.C_x[None],
                              np.zeros((1, 1))), w)
    ss_err = np.max(np.abs(casc.P_d(w)[i] / direct - 1))
    tf = control.ss2tf(control.ss(casc.A[i], casc.B_load[i][:, None], casc.C_x[None], 0))
    tf_err = np.max(np.abs(tf(1j * w) / direct - 1))
    assert ss_err < 1e-12 < tf_err


def test_controller_realisation(setup):
    w = np.logspace(-3, 4, 50)
    for G in (lti.thesis_position(), lti.thesis_velocity(), lti.thesis_prefilter()):
        A, B, C, D = G.ss()
        h = freqresp.ss_freqresp(A, B[:, 0], C[0], w, D[0, 0])[0]
        assert np.allclose(h, G.freq(w), rtol=1e-9)
        num, den = G.num_den()
        assert np.allclose(np.polyval(num, 1j * w) / np.polyval(den, 1j * w), G.freq(w), rtol=1e-8)
    G = lti.thesis_position()     # DC scaling of eq. 4.76 ~ 1.6e5 ("165200")
    assert abs(G.freq(1e-6) * 1e-6) == pytest.approx(1.614e5, rel=1e-3)


def test_second_order_section_realisation():
    """G of eq. 4.74 with a complex zero pair over a complex pole pair: the real cascade state
    space, the YAML polynomials and their roots reproduce the factored response; the section
    has unity DC gain, so K/s is untouched at low frequency."""
    w = np.logspace(-3, 4, 60)
    G = lti.position_controller(1e6, [190.0, 190.0, 0.5], [1500.0, 40.0, 1500.0],
                                [(800.0, 0.5, 1350.0, 0.56)])
    assert sum(isinstance(z, complex) for z in G.zeros) == 2 and len(G.poles) == 6
    A, B, C, D = G.ss()
    assert np.isrealobj(A) and A.shape == (6, 6)
    h = freqresp.ss_freqresp(A, B[:, 0], C[0], w, D[0, 0])[0]
    assert np.allclose(h, G.freq(w), rtol=1e-9)
    G2 = lti.from_num_den(*G.num_den())
    assert np.allclose(G2.freq(w), G.freq(w), rtol=1e-7)
    assert abs(G.freq(1e-6) * 1e-6) == pytest.approx(1e6, rel=1e-5)
    # the section alone has unity DC gain
    S = lti.position_controller(1.0, [], [], [(800.0, 0.5, 1350.0, 0.56)])
    assert abs(S.freq(1e-3) * 1e-3) == pytest.approx(1.0, rel=1e-6)
    with pytest.raises(ValueError):
        lti.Zpk((1 + 2j,), (-1.0, -2.0), 1.0)    # unpaired complex zero


def _spec_values(spec, w, L, Pd_abs):
    """Brute-force closed-loop spec ratios (<= 1 means met) of all plants at one frequency."""
    T = np.abs(L / (1 + L))
    S = np.abs(1 / (1 + L))
    return {'stability': T / spec['position.Ws'],
            'sensitivity': S / abs(spec.S_p(w)),
            'stiffness': Pd_abs * S / abs(spec.M(w))}


@pytest.mark.parametrize('name', ['stability', 'sensitivity', 'stiffness'])
def test_quadratic_bounds_vs_brute_force(setup, name):
    _, spec, _, casc = setup
    bs = qb.position_bounds(spec, casc.P_omega, casc.P_d)
    b = bs.specs[name]
    rng = np.random.default_rng(3)
    checked = 0
    for f, w in enumerate(bs.w):
        P = casc.P_omega(np.array([w]))[:, 0]
        Pd = np.abs(casc.P_d(np.array([w]))[:-1, 0])
        for k in rng.choice(len(b.phase_deg), 12, replace=False):
            psi = np.deg2rad(b.phase_deg[k])
            edges = []
            if b.lo[f, k] > 0:
                edges.append((b.lo[f, k], +1))          # above is fine, below violates
            if not np.isnan(b.fb_lo[f, k]):
                if b.fb_lo[f, k] > b.lo[f, k] * 1.01:
                    edges.append((b.fb_lo[f, k], -1))       # below is fine, above violates
                edges.append((b.fb_hi[f, k], +1))
            for g, sgn in edges:
                for eps, must_ok in ((1e-3, True), (-1e-3, False)):
                    l0 = g * (1 + sgn * eps)
                    L = l0 * np.exp(1j * psi) * P[:-1] / P[-1]
                    ratio = _spec_values(spec, w, L, Pd)[name].max()
                    if must_ok:
                        assert ratio <= 1 + 1e-9, (name, w, b.phase_deg[k], g)
                    else:
                        assert ratio > 1, (name, w, b.phase_deg[k], g)
                    checked += 1
    assert checked > 10


def test_tracking_bound_vs_brute_force(setup):
    _, spec, _, casc = setup
    bs = qb.position_bounds(spec, casc.P_omega, casc.P_d)
    b = bs.specs['tracking']
    for f, w in enumerate(bs.w):
        if w not in spec['position.track_freqs']:
            continue
        P = casc.P_omega(np.array([w]))[:, 0]
        allowed = qb.db(abs(spec.T_up(w)) / abs(spec.T_low(w))) + 2 * spec['position.track_tol_db']
        for k in range(0, len(b.phase_deg), 6):
            g = b.lo[f, k] if b.lo[f, k] > 0 else b.fb_hi[f, k]
            if not np.isfinite(g) or g <= 0:
                continue
            for eps, must_ok in ((1e-2, True), (-1e-2, False)):
                L = g * (1 + eps) * np.exp(1j * np.deg2rad(b.phase_deg[k])) * P[:-1] / P[-1]
                T = np.abs(L / (1 + L))
                spread = qb.db(T.max() / T.min())
                assert (spread <= allowed + 1e-9) == must_ok, (w, b.phase_deg[k])


def test_merge_most_restrictive(setup):
    _, spec, _, casc = setup
    bs = qb.position_bounds(spec, casc.P_omega, casc.P_d)
    m = bs.merged
    for b in bs.specs.values():
        ok = np.isnan(m.fb_lo)
        assert np.all(m.lo[ok] >= b.lo[ok])
    assert bs.merged.lo.shape == (len(spec.position_freqs), 73)


def test_pso_deterministic_and_converges():
    cost = lambda X: np.sum((X - 0.3) ** 2, axis=1)  # noqa: E731
    r1 = pso.pso(cost, [-1, -1, -1], [1, 1, 1], particles=20, iterations=40, seed=7)
    r2 = pso.pso(cost, [-1, -1, -1], [1, 1, 1], particles=20, iterations=40, seed=7)
    r3 = pso.pso(cost, [-1, -1, -1], [1, 1, 1], particles=20, iterations=40, seed=8)
    assert np.array_equal(r1.x, r2.x) and r1.history == r2.history
    assert not np.array_equal(r1.x, r3.x)
    assert r1.cost < 1e-3 and np.all(np.diff(r1.history) <= 0)


def test_loop_delay_in_position_responses(setup):
    """T_d = 1.5 Ts + drive.delay (2.5 ms) multiplies P_omega (not P_d); templates unchanged;
    the Pade state space matches e^{-j w T_d} well below 1/T_d."""
    plant, spec, fam, casc = setup
    Td = spec.loop_delay(fam.drive_delay)
    assert fam.drive_delay == plant['plant.drive.delay'] == 0.001
    assert Td == pytest.approx(1.5 * 0.001 + 0.001) and spec.delay_samples(fam.drive_delay) == 2
    over = QftSpec({**spec.values, 'digital.delay': 0.004})
    assert over.loop_delay(fam.drive_delay) == 0.004
    cd = family.CascadePlants(casc.A, casc.B_ref, casc.B_load, casc.C_x, casc.C_w, Td)
    w = np.logspace(-1, 3, 30)
    assert np.allclose(cd.P_omega(w), casc.P_omega(w) * np.exp(-1j * w * Td), rtol=1e-12)
    assert np.allclose(cd.P_d(w), casc.P_d(w), rtol=1e-12)
    q0 = casc.P_omega(w)[:-1] / casc.P_omega(w)[-1]
    assert np.allclose(cd.P_omega(w)[:-1] / cd.P_omega(w)[-1], q0, rtol=1e-9)
    A, B, C = cd.delayed_ss()
    wl = np.logspace(-1, np.log10(400), 12)
    h = freqresp.ss_freqresp(A[[0, -1]], B[[0, -1]], C[[0, -1]], wl)
    assert np.allclose(h, cd.P_omega(wl)[[0, -1]], rtol=2e-3)
    # the bounds see the delay only through L0: nominal L0 phase is lower by w T_d
    L0 = cd.P_omega(w)[-1] / casc.P_omega(w)[-1]
    assert np.allclose(np.angle(L0), np.angle(np.exp(-1j * w * Td)))


def test_zp_box_default_and_realisability(tmp_path):
    spec = default_spec()
    assert spec['position.zp_min'] == 0.5 and spec['position.zp_max'] == 1000.0
    bad = tmp_path / 'spec.yaml'
    bad.write_text('design_qft:\n  ros__parameters:\n    position: {zp_max: 2000.0}\n')
    with pytest.raises(ParamError) as err:
        load_spec(str(bad))
    msg = str(err.value)
    assert '\n' not in msg and 'position.zp_max' in msg and 'pi/(2 digital.Ts)' in msg


def test_digital_loop_matches_continuous_with_delay(setup):
    """ZOH plant + 2 shift states + Tustin G: nominal loop response, margins and max|T| agree
    with the continuous loop times e^{-j w T_d}; eigenvalues inside the unit circle."""
    _, spec, fam, casc = setup
    Td = spec.loop_delay(fam.drive_delay)
    cd = family.CascadePlants(casc.A, casc.B_ref, casc.B_load, casc.C_x, casc.C_w, Td)
    G = lti.thesis_position()
    dl = verify.digital_loop(cd, spec, fam)
    assert dl.nd == 2
    w = np.logspace(-1, np.log10(2500), 300)
    Lz = dl.loop_freq(G, w)
    Lc = cd.P_omega(w)[-1] * G.freq(w)
    low = w < 300
    assert np.max(np.abs(qb.db(np.abs(Lz[low] / Lc[low])))) < 0.3
    assert np.max(np.abs(np.angle(Lz[low] / Lc[low], deg=True))) < 3.0
    gz, pz = verify.margins(Lz[None], w)
    gc, pc = verify.margins(Lc[None], w)
    assert abs(gz[0] - gc[0]) < 1.0 and abs(pz[0] - pc[0]) < 5.0
    assert np.all(dl.max_abs_eig(G) < 1.0)
    # a loop gain beyond the digital GM is unstable in the discrete model
    k = 10 ** ((gz[0] + 2) / 20)
    Gk = lti.Zpk(G.zeros, G.poles, G.gain * k)
    assert dl.max_abs_eig(Gk)[-1] > 1.0
    # step: unit DC gain, starts at 0 (plant has no feed-through), approaches 1
    y = dl.steps(G, 1.0)
    assert abs(y[-1, -1] - 1) < 0.01 and y[-1, 0] == 0.0      # (slow tail of the 0.61 zero)


def test_step_metrics_and_filtered_steps():
    Ts = 0.001
    t = np.arange(1001) * Ts
    y = 1 - np.exp(-t / 0.05) * np.cos(40 * t)
    os_pct, ts = prefilter.step_metrics(y[None], Ts, 0.02)
    assert os_pct[0] == pytest.approx(100 * (y.max() - 1))
    k = np.nonzero(np.abs(y - 1) > 0.02)[0][-1]
    assert ts[0] == pytest.approx((k + 1) * Ts)
    assert np.isinf(prefilter.step_metrics(2 * t[None], Ts)[1][0])     # never settles
    # F applied to a step response by Tustin filtering == discrete F step (unit DC gain)
    F = lti.thesis_prefilter()
    ys = prefilter.filtered_steps(F, np.ones((1, 400)), Ts)
    assert abs(ys[0, -1] - 1) < 1e-6 and ys[0, 0] < 0.5


def test_minimax_refine_lowers_worst_excess(setup):
    """The dense-grid minimax step: its Ws part is max|T| over the family (direct evaluation),
    and a few SLSQP iterations from the thesis controller (eq. 4.76 in the eq. 4.74
    parametrisation) lower the worst spec excess without losing closed-loop stability."""
    _, spec, fam, casc = setup
    dx = minimax.DenseExcess(casc, spec)
    K = 2.668e9 * 447 * 153 * 0.61 / (2155 * 613 * 522)
    x0 = np.log10([447.0, 153.0, 0.61, 2155.0, 613.0, 522.0])
    G0 = cost.position_ctrl(x0, K)
    assert np.allclose(G0.freq(dx.w), lti.thesis_position().freq(dx.w), rtol=1e-9)
    L = casc.P_omega(dx.w) * G0.freq(dx.w)[None]
    T = np.abs(L / (1 + L)).max(0)
    assert np.allclose(dx.parts(G0)['Ws'], qb.db(T / spec['position.Ws']))
    e0 = dx(G0).max()
    assert dx.max_real(G0) < 0
    lo, hi = np.full(6, np.log10(0.5)), np.full(6, np.log10(3000.0))
    x, e = minimax.refine(lambda v: cost.position_ctrl(v, K), x0, lo, hi, dx, -0.25, maxiter=40)
    assert e < e0 - 1.0, (e0, e)
    assert dx.max_real(cost.position_ctrl(x, K)) <= -0.25


def test_bound_margin_matches_violation(setup):
    """margin_db (signed, used by the minimax step) equals violation_db where a bound is
    violated and is <= 0 where it is met, for the thesis loop and the same loop 10 dB up."""
    _, spec, fam, casc = setup
    bs = qb.position_bounds(spec, casc.P_omega, casc.P_d)
    for k in (1.0, 10 ** 0.5):
        L0 = k * casc.P_omega(bs.w)[-1] * lti.thesis_position().freq(bs.w)
        v, m = qb.violation_db(bs.merged, L0), qb.margin_db(bs.merged, L0)
        assert np.allclose(m[v > 0], v[v > 0]) and np.all(m[v == 0] <= 1e-12)
        assert np.any(v > 0) and np.any(m < 0)
