"""Fault injection: each fault changes the measured state as documented; timing; rejection."""
import math

import numpy as np
import pytest

from eha_ros.core.sim.pid_loop import make_plant, plant_loop as closed_loop


def _quiet():
    return make_plant({'plant.sensors.noise': False})


def _run(plant, n, w=100.0, load=0.0):
    for _ in range(n):
        plant.step(w, load)


def test_unknown_and_bad_faults_rejected():
    plant = _quiet()
    ok, msg = plant.inject_fault('warp_core_breach', 0, 1.0, 0.0)
    assert not ok and 'unknown fault' in msg and 'msp_bias' in msg
    assert not plant.inject_fault('motor_fail', 2, 1.0, 0.0)[0]
    assert not plant.inject_fault('msp_bias', 0, math.nan, 0.0)[0]
    assert not plant.inject_fault('msp_bias', 0, 1e-3, -1.0)[0]
    assert not plant.inject_fault('pump_leakage', 0, -2.0, 0.0)[0]
    ok, msg = plant.inject_fault('msp_bias', 0, 1e9, 0.0)     # beyond the sensor's range
    assert not ok and 'sensor range' in msg and not plant.faults.active
    assert not plant.inject_fault('msp_drift', 0, -1e3, 0.0)[0]


def test_clear_removes_permanent_faults():
    plant = _quiet()
    _run(plant, 10)
    assert plant.inject_fault('msp_bias', 0, 1e-3, 0.0)[0]      # permanent
    assert plant.inject_fault('pressure_sensor', 0, 1e5, 0.0)[0]
    _run(plant, 5)
    assert plant.measure().position - plant.truth().position == pytest.approx(1e-3, abs=1.5e-6)
    ok, msg = plant.inject_fault('clear', 0, 0.0, 0.0)
    assert ok and 'cleared 2' in msg
    _run(plant, 2)
    m, tr = plant.measure(), plant.truth()
    assert abs(m.position - tr.position) < 1.5e-6
    assert abs(m.pressure_a - tr.pressure_a) < 1e3
    assert plant.inject_fault('clear', 0, 0.0, 0.0) == (True, 'cleared 0 active fault(s)')


def test_msp_bias_shifts_measured_position_and_expires():
    plant = _quiet()
    _run(plant, 10)
    ok, msg = plant.inject_fault('msp_bias', 0, 1e-3, 0.1)
    assert ok, msg
    _run(plant, 5)
    m, tr = plant.measure(), plant.truth()
    assert m.position - tr.position == pytest.approx(1e-3, abs=1.5e-6)
    _run(plant, 100)
    m, tr = plant.measure(), plant.truth()
    assert abs(m.position - tr.position) < 1.5e-6          # duration over: healthy again


def test_msp_drift_grows_linearly():
    plant = _quiet()
    plant.inject_fault('msp_drift', 0, 0.01, 0.0)
    _run(plant, 200)
    off = plant.measure().position - plant.truth().position
    assert off == pytest.approx(0.01 * 0.2, rel=0.02)


def test_msp_noise_adds_white_noise():
    plant = _quiet()
    plant.inject_fault('msp_noise', 0, 1e-4, 0.0)
    err = []
    for _ in range(2000):
        plant.step(0.0)
        err.append(plant.measure().position - plant.truth().position)
    assert np.std(err) == pytest.approx(1e-4, rel=0.1)


def test_msp_stuck_freezes_output():
    plant = _quiet()
    _run(plant, 10)
    plant.inject_fault('msp_stuck', 0, 0.0, 0.0)
    _run(plant, 1)
    frozen = plant.measure().position
    _run(plant, 100)
    assert plant.measure().position == frozen
    assert abs(plant.truth().position - frozen) > 1e-3


def test_motor_fail_zero_current_torque_and_speed_decays():
    plant = _quiet()
    _run(plant, 200, w=300.0)
    assert plant.measure().motor_speed[0] > 250
    ok, _ = plant.inject_fault('motor_fail', 0, 1.0, 0.3)
    assert ok
    _run(plant, 2, w=300.0)
    m = plant.measure()
    assert m.drive_fault[0] and not m.drive_fault[1]
    assert m.motor_current[0] == 0.0
    speeds = []
    for _ in range(100):
        plant.step(300.0)
        speeds.append(plant.measure().motor_speed[0])
        assert plant.measure().motor_current[0] == 0.0
    assert speeds[-1] < 0.5 * speeds[0] and np.all(np.diff(speeds) < 1e-9)
    _run(plant, 300, w=300.0)                     # fault over: the drive recovers
    m = plant.measure()
    assert not m.drive_fault[0] and m.motor_speed[0] > 250


def test_pump_leakage_needs_more_motor_speed_to_hold_load():
    def holding_speed(mult):
        plant = _quiet()
        if mult != 1.0:
            plant.inject_fault('pump_leakage', 0, mult, 0.0)
        run = closed_loop(plant, 2.0, lambda t: 0.0, lambda t: 10e3)
        return run['w'][0][run['t'] > 1.5].mean()
    w1, w10 = holding_speed(1.0), holding_speed(10.0)
    # leakage at p_D ~ 39 bar: the pump's share C_p + C_r/2 of C_eq grows 10x
    assert w10 > 5.0 * w1 > 0


def test_pressure_sensor_bias_and_stuck():
    plant = _quiet()
    _run(plant, 10)
    plant.inject_fault('pressure_sensor', 0, 2e5, 0.05)
    _run(plant, 1)
    m, tr = plant.measure(), plant.truth()
    assert m.pressure_a - tr.pressure_a == pytest.approx(2e5)
    assert m.pressure_b - tr.pressure_b == pytest.approx(2e5)
    _run(plant, 60)
    assert plant.measure().pressure_a == pytest.approx(plant.truth().pressure_a)
    ok, _ = plant.inject_fault('pressure_sensor', 0, math.nan, 0.0)
    assert ok
    _run(plant, 1)
    frozen = plant.measure().pressure_a
    _run(plant, 100, load=20e3)
    assert plant.measure().pressure_a == frozen
    assert abs(plant.truth().pressure_a - frozen) > 10e5


@pytest.mark.parametrize('side', ['a', 'b'])
def test_one_pressure_sensor_bias_and_stuck(side):
    """pressure_sensor_a / _b: only that chamber's reading is biased or frozen, the other reads
    the truth; a bias on one side plus one on both add up."""
    plant = _quiet()
    _run(plant, 10)
    own, other = f'pressure_{side}', f'pressure_{"b" if side == "a" else "a"}'
    assert plant.inject_fault(f'pressure_sensor_{side}', 1, -3e5, 0.05)[0]
    _run(plant, 1)
    m, tr = plant.measure(), plant.truth()
    assert getattr(m, own) - getattr(tr, own) == pytest.approx(-3e5)
    assert getattr(m, other) == getattr(tr, other)
    assert plant.inject_fault('pressure_sensor', 0, 1e5, 0.05)[0]
    _run(plant, 1)
    m, tr = plant.measure(), plant.truth()
    assert getattr(m, own) - getattr(tr, own) == pytest.approx(-2e5)
    assert getattr(m, other) - getattr(tr, other) == pytest.approx(1e5)
    _run(plant, 60)
    m, tr = plant.measure(), plant.truth()
    assert (m.pressure_a, m.pressure_b) == (tr.pressure_a, tr.pressure_b)
    assert plant.inject_fault(f'pressure_sensor_{side}', 0, math.nan, 0.0)[0]
    _run(plant, 1)
    frozen = getattr(plant.measure(), own)
    _run(plant, 100, load=20e3 if side == 'a' else -20e3)    # loads the stuck sensor's chamber
    m, tr = plant.measure(), plant.truth()
    assert getattr(m, own) == frozen and abs(getattr(tr, own) - frozen) > 10e5
    assert getattr(m, other) == getattr(tr, other)
