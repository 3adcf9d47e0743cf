"""Linear models (eq. 3.24, 3.35, 3.41, 4.35) vs thesis poles and vs the nonlinear plant."""
import math

import numpy as np
import pytest

from eha_ros.core.plant import linear as lin
from eha_ros.core.plant.parameters import nominal_plant
from eha_ros.core.sim.pid_loop import make_plant

P = nominal_plant()


def _hydraulic_pair(poles):
    pair = [p for p in poles if p.imag > 3000]
    assert len(pair) == 1, poles
    return pair[0]


@pytest.mark.parametrize('abcd', [lin.hydromech_abcd(P), lin.voltage_abcd(P), lin.torque_abcd(P),
                                  lin.velocity_abcd(P), lin.velocity_abcd(P, lowpass=True)],
                         ids=['4.35', '3.24', '3.35', '3.41', '3.41+lowpass'])
def test_integrator_and_lightly_damped_hydraulic_pair(abcd):
    poles = lin.poles(abcd)
    assert abs(poles[0]) < 1e-6                    # the position integrator
    assert all(p.real < 1e-9 for p in poles)       # everything else stable
    hp = _hydraulic_pair(poles)
    wn = abs(hp)
    zeta = -hp.real / wn
    assert 4000 < wn < 5500 and zeta < 0.1, (wn, zeta)


# thesis velocity-loop gains of eq. 4.71; config/plant.yaml carries the design_qft gains
THESIS_DRIVE = {'plant.drive.Kp_w': 0.45, 'plant.drive.Ki_w': 56.0, 'plant.drive.lowpass_w': 2555.0}


def test_velocity_loop_poles_match_eq_4_72():
    P = nominal_plant(THESIS_DRIVE)
    poles = lin.poles(lin.velocity_loop_abcd(P))
    slow = sorted(abs(p) for p in poles if 1 < abs(p) < 4000)
    thesis = sorted([530.6, 158.3, math.sqrt(7.257e6), math.sqrt(7.257e6)])
    assert len(slow) == 4
    for ours, ref in zip(slow, thesis):
        assert abs(ours / ref - 1) < 0.05, (slow, thesis)
    z, _, k = lin.zpk(lin.velocity_loop_abcd(P))
    finite = sorted(abs(zz) for zz in z if 10 < abs(zz) < 4000)
    assert np.allclose(finite, [125, 1250], rtol=0.02)      # zeros of eq. 4.72
    assert abs(k / 3.9019e6 - 1) < 0.1


def test_voltage_model_pole_structure_table_4_3():
    poles = lin.poles(lin.voltage_abcd(P))
    motor = [p for p in poles if 100 < abs(p) < 2000 and p.imag > 0][0]
    assert abs(abs(motor) / 662.3 - 1) < 0.2               # Table 4.3 (k_E/b_eq choices)


def test_low_frequency_gain_is_Dp_over_Ap():
    for abcd in (lin.hydromech_abcd(P), lin.velocity_abcd(P)):
        w = 0.1
        h = lin.freqresp(abcd, [w])[0] * 1j * w           # remove the integrator
        assert abs(abs(h) / (P['plant.pump.D_p'] / P['plant.cylinder.A_p']) - 1) < 0.01


def test_eq_4_35_is_stable_with_corrected_sign_and_force_along_plus_x():
    A, B, C, D = lin.hydromech_abcd(P)
    assert A[1, 2] > 0                                      # +A_p/m_p (eq. 3.24)
    # static compliance sign: a force along +x moves the piston to +x
    s = 1e-3
    xf = (C @ np.linalg.solve(s * np.eye(3) - A, B[:, 1]))[0]
    assert xf.real > 0
    # eq. 3.41: positive F_L pushes towards -x
    A7, B7, C7, _ = lin.velocity_abcd(P)
    assert B7[3, 1] < 0


def _fit(t, y, f):
    """Least squares y = a sin + b cos + c + d t; returns complex amplitude a + j b ~ e^{j phi}."""
    w = 2 * math.pi * f
    M = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t), t])
    coef = np.linalg.lstsq(M, y, rcond=None)[0]
    return complex(coef[0], coef[1])


@pytest.mark.parametrize('f', [0.1, 0.5, 1.0, 3.0, 7.0, 10.0, 15.0])
def test_linear_matches_nonlinear_frequency_response(f):
    """Nonlinear plant (viscous friction only, no drive delay, no noise) vs eq. 3.41 with the
    low-pass; input a 20 rad/s sine on omega_ref held over each tick (ZOH accounted for)."""
    plant = make_plant({'plant.friction.model': 'viscous', 'plant.drive.delay': 0.0,
                        'plant.sensors.noise': False})
    Ts = plant.Ts
    amp = 20.0
    settle = max(0.5, 1.0 / f)
    periods = max(1, int(round(2.0 * f)))
    n0 = int(round(settle / Ts))
    n = n0 + int(round(periods / f / Ts))
    k = np.arange(n)
    u = amp * np.sin(2 * math.pi * f * k * Ts)
    x = plant.run(u)
    t = (k + 1) * Ts                                 # x[k] is the state after tick k
    meas = _fit(t[n0:], x[n0:], f) / amp             # sine coefficient -> response
    w = 2 * math.pi * f
    zoh = (1 - np.exp(-1j * w * Ts)) / (1j * w * Ts)
    model = lin.freqresp(lin.velocity_abcd(P, lowpass=True), [w])[0] * zoh
    # sin input -> output Im-part convention: y = |G| sin(wt + phi) = a sin + b cos, a+jb = G
    gain_db = 20 * math.log10(abs(meas) / abs(model))
    phase = math.degrees(np.angle(meas / model))
    print(f'{f:5.1f} Hz: gain diff {gain_db:+.3f} dB, phase diff {phase:+.2f} deg')
    assert abs(gain_db) < 1.0
    assert abs(phase) < 5.0
