"""Integration accuracy (step halving), robustness to bad inputs, options that change numerics."""
import math

import numpy as np
import pytest

from eha_ros.core.plant import layout as L
from eha_ros.core.sim.pid_loop import make_plant, plant_loop as closed_loop


def _step_response(substeps, **extra):
    over = {'plant.sim.substeps': substeps, 'plant.sensors.noise': False}
    over.update(extra)
    return closed_loop(make_plant(over), 1.0, lambda t: 5e-3)['x']


def test_halving_substep_changes_step_response_below_0p1_percent():
    x16 = _step_response(16)
    x32 = _step_response(32)
    diff = np.abs(x16 - x32).max()
    print(f'5 mm step, h = 62.5 -> 31.25 us: max |dx| = {diff * 1e6:.3f} um '
          f'= {diff / 5e-3 * 100:.4f} % of range')
    assert diff < 1e-3 * 5e-3
    assert abs(x16[-1] - 5e-3) < 50e-6                      # it did track the step


def test_non_finite_inputs_rejected_and_state_untouched():
    plant = make_plant()
    for _ in range(10):
        plant.step(50.0)
    before = plant.S.copy()
    t = plant.t
    for bad in [(math.nan, 0.0), (math.inf, 0.0), (0.0, math.nan), (-math.inf, math.inf)]:
        with pytest.raises(ValueError):
            plant.step(*bad)
    assert np.array_equal(plant.S, before) and plant.t == t
    plant.step(50.0)
    assert np.all(np.isfinite(plant.S)) and plant.measure().valid


def test_huge_finite_inputs_are_limited_not_fatal():
    plant = make_plant({'plant.sensors.noise': False})
    for _ in range(300):
        plant.step(1e9, 1e5)            # clamped at 8000 rpm; 100 kN > 65 kN relief force
    tr = plant.truth()
    assert np.all(np.isfinite(plant.S))
    assert abs(tr.motor_speed[0]) <= plant.p.omega_max * 1.05
    assert -plant.p.x_stop - 1e-3 < tr.position < -plant.p.x_stop   # pushed into the stop
    assert tr.pressure_a < plant.p.relief_crack + tr.pressure_acc + 30e5
    assert plant.S[L.S_QREL] > 0                                # relief valve is open


def test_end_stop_holds_the_piston():
    plant = make_plant({'plant.sensors.noise': False})
    plant.reset(position=0.055)
    for _ in range(200):
        plant.step(300.0)
    tr = plant.truth()
    # pump dead-heads against the stop: A at the relief setting, stop force ~ A_p * p_D
    assert tr.pressure_a == pytest.approx(plant.p.relief_crack + tr.pressure_acc, rel=0.05)
    pen = plant.p.A_p * (tr.pressure_a - tr.pressure_b) / plant.p.stop_k
    assert tr.position == pytest.approx(plant.p.x_stop + pen, rel=1e-3)


@pytest.mark.parametrize('over', [{'plant.motor.model': 'dq'},
                                  {'plant.pump.leakage_model': 'table'},
                                  {'plant.sim.substeps': 32}])
def test_options_give_the_same_step_response(over):
    ref = _step_response(16)
    x = _step_response(over.pop('plant.sim.substeps', 16), **over)
    assert np.abs(x - ref).max() < 0.05 * 5e-3                # same physics, within 5 %
    assert abs(x[-1] - 5e-3) < 50e-6


def test_dq_motor_holds_i_d_at_zero():
    plant = make_plant({'plant.motor.model': 'dq', 'plant.sensors.noise': False})
    from eha_ros.core.plant import layout as L
    for _ in range(100):
        plant.step(500.0)
    assert abs(plant.S[L.S_CH + L.C_ID]) < 0.05 * max(1.0, abs(plant.S[L.S_CH + L.C_I]))
    assert plant.truth().motor_speed[0] == pytest.approx(500.0, rel=0.02)


def test_reproducible_noise_with_seed():
    a, b, c = make_plant(seed=3), make_plant(seed=3), make_plant(seed=4)
    xa, xb, xc = [], [], []
    for _ in range(50):
        for p, out in ((a, xa), (b, xb), (c, xc)):
            p.step(10.0)
            out.append(p.measure().position)
    assert xa == xb and xa != xc


def test_truth_carries_the_sensor_offset_of_the_same_measurement():
    """Truth.position_sensor_offset is the Gauss-Markov offset inside the measured position of
    the same tick: without the white noise and the quantisation, measured = truth + offset
    exactly, at reset and after every tick, across new noise blocks."""
    from eha_ros.core.plant.sensors import BLOCK
    plant = make_plant({'plant.sensors.position_sigma': 0.0,
                        'plant.sensors.position_resolution': 0.0}, seed=5)
    offsets = []
    for k in range(BLOCK + 50):
        if k:
            plant.step(200.0 * math.sin(0.01 * k), 3e3)
        m, tr = plant.measure(), plant.truth()
        assert m.position == tr.position + tr.position_sensor_offset, k
        offsets.append(tr.position_sensor_offset)
    assert 5e-6 < np.std(offsets) < 50e-6              # the 20 um Gauss-Markov process


def test_reset_and_new_noise_blocks_write_into_the_kernels_record():
    """The compiled step's arrays (EhaPlant.arrays, one record) are made with the plant: new
    noise blocks and reset() write into them, none can be replaced, and a plant reset after
    more than two noise blocks and a fault repeats a fresh one bit for bit."""
    from eha_ros.core.plant.sensors import BLOCK
    a, fresh = make_plant(seed=3), make_plant(seed=3)
    record = a.arrays
    arrays = [id(x) for x in record]

    def run(plant, n):
        out = []
        for k in range(n):
            plant.step(300.0 * math.sin(0.004 * k), 5e3 * math.sin(0.002 * k))
            out.append((plant.S.copy(), plant.arrays.meas.copy(), plant.t))
        return out

    run(a, 2 * BLOCK + 300)
    assert a.inject_fault('msp_bias', 0, 1e-3, 0.0)[0]
    a.reset(0.01)
    fresh.reset(0.01)
    assert a.arrays is record and [id(x) for x in a.arrays] == arrays
    assert a._noise.block is record.block and a._delay.ring is record.ring
    with pytest.raises(AttributeError):
        a.S = a.S.copy()
    for got, want in zip(run(a, BLOCK + 10), run(fresh, BLOCK + 10)):
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
        assert got[2] == want[2]


def test_oil_is_conserved():
    """Chamber oil + accumulator oil is constant (closed circuit, eq. 3.19 and 3.18)."""
    from eha_ros.core.plant import layout as L
    plant = make_plant({'plant.sensors.noise': False})
    p = plant.p

    def oil():
        S = plant.S
        va = p.V_d + p.A_p * S[L.S_X]
        vb = p.V_d - p.A_p * S[L.S_X]
        # linear compressibility: mass ~ V (1 + p / beta)
        return va * (1 + S[L.S_PA] / p.beta) + vb * (1 + S[L.S_PB] / p.beta) + S[L.S_VOIL]

    o0 = oil()
    for k in range(1000):
        plant.step(300.0 * math.sin(2 * math.pi * 2 * k * 1e-3), 5e3)
    assert abs(oil() - o0) < 1e-3 * 1e-6 * 1e3               # < 1 mm^3 of oil
