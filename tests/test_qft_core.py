"""QFT toolchain core: family, state-space frequency responses, bounds vs brute force, PSO."""
import numpy as np
import pytest

from eha_ros.core.params import load
from eha_ros.core.plant import linear
from eha_ros.core.plant.parameters import PLANT_SCHEMA
from eha_ros.core.qft import bounds as qb
from eha_ros.core.qft import family, freqresp, lti, pso
from eha_ros.core.qft.spec import default_spec


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
    """Nominal closed velocity loop with the thesis G_v equals linear.velocity_abcd(lowpass)."""
    plant, _, _, casc = setup
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
