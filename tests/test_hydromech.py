"""The hydromechanical model derived once (core.plant.hydromech): the linear models, the eq. 4.35
filter and the chamber filter use its matrices to the bit, and they agree with each other and
with the thesis' poles."""
import dataclasses
import itertools

import numpy as np
import pytest

from eha_ros.core.estimator import chamber_kf, model_kf
from eha_ros.core.plant import hydromech as hm
from eha_ros.core.plant import linear as lin
from eha_ros.core.plant.parameters import PlantParams, nominal_plant
from eha_ros.core.qft.family import scaled_params

BASE = nominal_plant()
# the nominal plant and the corners of Table 4.5 [C_eq, D_p, beta, k_T, k_E]
SCALES = [(1, 1, 1, 1, 1), (0.1, 0.8, 0.7, 0.8, 1.2), (10, 1, 1.4, 1.2, 0.8)]
PLANTS = [scaled_params(BASE, s) for s in SCALES]


@pytest.mark.parametrize('plant', PLANTS, ids=[str(s) for s in SCALES])
def test_linear_models_and_eq_4_35_filter_use_the_load_pressure_rows(plant):
    pp = PlantParams.from_dict(plant)
    A3, B3 = hm.load_pressure(hm.hydromech(pp))
    A, B, _, _ = lin.hydromech_abcd(plant)
    assert np.array_equal(A, A3) and np.array_equal(B, B3)
    rows = [2, 3, 4]                         # x, xdot, p_D in eq. 3.24, 3.35, 3.41
    for A5, B5 in ((lin.voltage_abcd(plant, True)[:2]), lin.torque_abcd(plant)[:2],
                   lin.velocity_abcd(plant)[:2], lin.velocity_abcd(plant, True)[:2]):
        assert np.array_equal(A5[np.ix_(rows, rows)], A3)
        assert np.array_equal(A5[rows, 1], B3[:, 0])          # the pump flow of the shaft w
        if B5.shape[1] > 1:
            assert B5[3, 1] == -B3[1, 1]                       # F_L towards -x (eq. 3.23)
    for leakage in hm.LEAKAGE:
        h = hm.hydromech(pp, leakage)
        Ah, Bh = hm.load_pressure(h)
        for corner in (None, 1.0):
            Af, Bf = model_kf.continuous(h, corner)
            assert np.array_equal(Af[:3, :3], Ah) and np.array_equal(Bf[:3], Bh)


def test_leakage_variants():
    pp = PlantParams.from_dict(BASE)
    A22 = {k: hm.load_pressure(hm.hydromech(pp, k))[0][2, 2] for k in hm.LEAKAGE}
    assert A22['eq3_22'] == 2.0 * A22['eq4_35']        # eq. 4.35 prints half of eq. 3.22
    assert hm.hydromech(pp, 'boost').C_eq == pp.C_p + pp.C_c + pp.C_r
    assert hm.hydromech(pp).C_eq == pp.C_eq == pp.C_p + pp.C_c + 0.5 * pp.C_r
    with pytest.raises(ValueError, match='eq3_22'):
        hm.hydromech(pp, 'printed')


@pytest.mark.parametrize('plant', PLANTS, ids=[str(s) for s in SCALES])
def test_chamber_filter_uses_the_chamber_form(plant):
    c = hm.circuit(PlantParams.from_dict(plant))
    for s_a, s_b in itertools.product((False, True), repeat=2):
        A, B = hm.chamber(c, s_a, s_b)
        for corner in (None, 1.0):
            Af, Bf = chamber_kf.continuous(c, s_a, s_b, corner)
            assert np.array_equal(Af[:4, :4], A) and np.array_equal(Bf[:4], B)
        # the pressure block is the leakage (and open check valve) part, written once
        AL = hm.chamber_leakage(c, 4, 'xr', s_a, s_b)
        assert np.array_equal(A[2:, 2:], AL[2:, 2:])
    assert np.array_equal(hm.chamber_flow_columns(c)[2:], c.k * np.eye(2))


@pytest.mark.parametrize('plant', PLANTS, ids=[str(s) for s in SCALES])
@pytest.mark.parametrize('valves', [False, True], ids=['shut', 'open'])
def test_chamber_form_at_equal_valve_states_is_the_load_pressure_form(plant, valves):
    """p_A' - p_B' with both check valves in the same state is eq. 3.22's p_D row with C_eq
    (+ K_c/2 with both open: the p_c terms cancel), and the rest is eq. 3.23."""
    pp = PlantParams.from_dict(plant)
    c = hm.circuit(pp)
    h = hm.hydromech(pp)
    if valves:
        h = dataclasses.replace(h, C_eq=h.C_eq + 0.5 * c.K_c)
    A, B = hm.chamber(c, valves, valves)
    A3, B3 = hm.load_pressure(h)
    rng = np.random.default_rng(1)
    for _ in range(5):
        x, v, pa, pb = rng.normal(size=4) * (1e-3, 1e-2, 1e6, 1e6) + (0, 0, 1e6, 1e6)
        w, fl = rng.normal(size=2) * (100.0, 300.0)
        d = A @ (x, v, pa, pb) + B @ (w, fl, 1.0)
        d3 = A3 @ (x, v, pa - pb) + B3 @ (w, fl)
        assert d[2] - d[3] == pytest.approx(d3[2], rel=1e-9)
        assert d[1] == pytest.approx(d3[1], rel=1e-12) and d[0] == d3[0]


def test_poles_of_both_forms():
    """The lightly damped hydraulic pair of eq. 4.35 (the linear models' test of the thesis
    pole structure: 4000 < w_n < 5500 rad/s, zeta < 0.1) and the position integrator; the
    chamber form with both valves shut has the same poles plus the common mode of both
    chambers draining to the accumulator, -beta C_r/V_d."""
    pp = PlantParams.from_dict(BASE)
    ev3 = np.linalg.eigvals(hm.load_pressure(hm.hydromech(pp))[0])
    c = hm.circuit(pp)
    ev4 = np.linalg.eigvals(hm.chamber(c, False, False)[0])
    pair = [p for p in ev3 if p.imag > 3000]
    assert len(pair) == 1 and 4000 < abs(pair[0]) < 5500 and -pair[0].real / abs(pair[0]) < 0.1
    assert min(abs(ev3)) < 1e-6
    expect = np.sort_complex(np.append(ev3, -c.k * c.C_r))
    assert np.allclose(np.sort_complex(ev4), expect, rtol=1e-9, atol=1e-6)
