"""The fast batch closed loop (core.sim.batch.BatchLoop with core.sim.closed_loop segments)
reproduces the tick-by-tick reference path bit for bit: plant, estimator, controller and switch
manager, over a load step, a commanded switch, faults (motor_fail, timed sensor faults, rejected
pressures) and BatchStack's loop without the manager."""
import math

import numpy as np
import pytest

from eha_ros.core.sim.batch import BatchStack
from eha_ros.core.sim import switchover as B

T_SWITCH = 1.5
T_FAIL = 2.5


def same(a: dict, b: dict) -> list:
    """Names of the arrays that differ (NaN equal to NaN)."""
    return [k for k, v in a.items() if isinstance(v, np.ndarray)
            and not np.array_equal(v, b[k], equal_nan=v.dtype.kind == 'f')]


def events(r) -> list:
    return [e.to_dict() for e in r['manager'].events]


@pytest.fixture(scope='module')
def table_3_4():
    """Table 3.4-like: 3 Hz 3 mm sine, 10 kN load step at 1 s, commanded switch A -> B at
    1.5 s, motor_fail on B at 2.5 s (automatic switch back to A), 3.2 s in all."""
    scn = B.Scenario(duration=3.2, commands=[(T_SWITCH, 1, 'Table 3.4')],
                     faults=[(T_FAIL, 'motor_fail', 1, 0.0, 0.0)])
    return {mode: B.run(scn, switch_hold=0.02, fast=mode == 'fast') for mode in ('ref', 'fast')}


def test_table_3_4_bit_identical(table_3_4):
    ref, fast = table_3_4['ref'], table_3_4['fast']
    assert same(ref, fast) == []
    assert events(ref) == events(fast)
    assert ref['responses'] == fast['responses']
    # the scenario covers what it claims: load step, commanded switch, automatic switch
    kinds = [e['kind'] for e in events(ref)]
    assert kinds == ['switch_start', 'switch_done', 'switch_start', 'switch_done']
    assert events(ref)[0]['commanded'] and not events(ref)[2]['commanded']
    assert fast['manager'].name == 'DEGRADED' and fast['manager'].channel_healthy == [True, False]
    n = len(ref['t'])
    assert ref['fast_ticks'] == 0 and fast['fast_ticks'] > 0.98 * n      # really compiled
    assert np.abs(ref['x'] - ref['ref']).max() < 2e-3                      # and tracking


def test_timed_sensor_faults_and_rejections_bit_identical():
    """Fault expiry (msp_noise, msp_drift, stuck pressures), rejected pressures (Python ticks
    inside a run), a refused command and commands in a row; the 2 mm drift is a position
    fault: the safe state (core.loop.safe_state), found by a compiled tick that is rolled back and
    done again in Python."""
    scn = B.Scenario(duration=2.4, faults=[(0.5, 'msp_noise', 0, 5e-5, 0.7),
                                           (1.0, 'msp_drift', 0, 2e-3, 0.8),
                                           (1.8, 'pressure_sensor', 0, math.nan, 0.1)],
                     commands=[(0.3, 1, 'first'), (0.31, 0, 'refused'), (2.0, 0, 'back')])
    ref, fast = (B.run(scn, switch_hold=0.02, fast=f) for f in (False, True))
    assert same(ref, fast) == []
    assert events(ref) == events(fast)
    kinds = [e['kind'] for e in events(ref)]
    assert 'refused' in kinds
    # the 2 mm drift, then its end (the reading jumps back 2 mm while the estimate is away):
    # a position fault, the safe state: hydraulic lock and zero speed
    safe = [e for e in ref['manager'].events if e.kind == 'safe']
    print([(e.t, e.reason) for e in safe])
    assert safe and 'position fault' in safe[0].reason
    assert 1.0 < safe[0].t < 1.9 and ref['manager'].state == 'FAILED_SAFE'
    locked = np.asarray(ref['t']) > safe[0].t + 0.0015
    assert np.all(np.asarray(ref['w_ref'])[locked] == 0.0)
    assert ref['responses'] == fast['responses']
    # the estimator isolates the position sensor while it reports a jump or a stuck sensor
    # (estimator.fault.isolate): those ticks (msp_noise, msp_drift + hold) run in Python
    assert 0.4 * len(ref['t']) < fast['fast_ticks'] < len(ref['t'])


def test_without_estimator_bit_identical():
    scn = B.Scenario(duration=1.5, commands=[(1.0, 1, 'no estimator')])
    ref, fast = (B.run(scn, use_estimator=False, fast=f) for f in (False, True))
    assert not ref['estimator'] and same(ref, fast) == [] and events(ref) == events(fast)


def test_batch_stack_run_equals_ticks():
    n = 1500
    t = np.arange(n) * 1e-3
    refs = 2e-3 * np.sin(2 * np.pi * 5.0 * t)
    loads = np.where(t >= 0.8, 5e3, 0.0)
    a, b, c = BatchStack(seed=3), BatchStack(seed=3), BatchStack(seed=3)
    ticks = [a.tick(r, f) for r, f in zip(refs, loads)]     # the compiled tick, one by one
    fast = b.run(refs[:700], loads[:700])                   # in segments
    rest = b.run(refs[700:], loads[700:])
    slow = c.run(refs, loads, fast=False)                   # the Python objects
    for name in ('seq', 'reference', 'measured', 'estimate', 'truth', 'command',
                 'motor_speed_0', 'motor_speed_1', 'active_channel'):
        col = np.concatenate((fast[name], rest[name]))
        assert np.array_equal(col, [getattr(tk, name) for tk in ticks]), name
        assert np.array_equal(col, slow[name]), name
    assert b.k == a.k == c.k == n
    assert b._loop.fast_ticks >= n - 2 and a._loop.fast_ticks >= n - 2
    assert c._loop.fast_ticks == 0


@pytest.mark.parametrize('over', [{'estimator.filter': 'pva'},
                                  {'estimator.measurements': 'position'},
                                  {'estimator.model.structure': 'eq4_35'},
                                  {'estimator.model.friction_pressure': True}])
def test_estimator_variants_bit_identical(over):
    """PVA filter, position-only model KF, and a fault-isolating estimator (predict-only
    ticks after the load step's innovation jump: Python ticks) through BatchStack."""
    n = 1500
    t = np.arange(n) * 1e-3
    refs, loads = 2e-3 * np.sin(2 * np.pi * 3.0 * t), np.where(t > 0.8, 8e3, 0.0)
    ov = {'estimator': {f'estimator:{k}': v for k, v in over.items()}}
    a, b, c = (BatchStack(seed=2, overrides=ov) for _ in range(3))
    ticks = [a.tick(r, f) for r, f in zip(refs, loads)]
    fast = b.run(refs, loads)
    slow = c.run(refs, loads, fast=False)
    for name in ('estimate', 'command', 'truth', 'measured'):
        assert np.array_equal(fast[name], [getattr(tk, name) for tk in ticks]), name
        assert np.array_equal(fast[name], slow[name]), name
    assert b._loop.fast_ticks > 700


def test_non_finite_input_is_the_python_error():
    """A segment never answers where the per-tick path would not: a NaN load raises the
    plant's ValueError at that tick, with everything before it done."""
    stack = BatchStack()
    loads = np.zeros(400)
    loads[300] = math.nan
    with pytest.raises(ValueError, match='non-finite plant input'):
        stack.run(np.zeros(400), loads)
    assert stack.plant.t == pytest.approx(0.3)


def test_batch_stack_run_equals_ticks_through_an_acceleration_limited_step():
    """A jumped reference takes the shaper's acceleration-limited move (control.accel_limit)."""
    n = 1200
    refs = np.where(np.arange(n) >= 200, 5e-3, 0.0)
    loads = np.zeros(n)
    a, b, c = BatchStack(seed=4), BatchStack(seed=4), BatchStack(seed=4)
    ticks = [a.tick(r, f) for r, f in zip(refs, loads)]
    fast = b.run(refs, loads)
    slow = c.run(refs, loads, fast=False)
    for name in ('reference', 'estimate', 'truth', 'command'):
        assert np.array_equal(fast[name], [getattr(tk, name) for tk in ticks]), name
        assert np.array_equal(fast[name], slow[name]), name
    assert a.controller.ref.rate == b.controller.ref.rate == 0.0
    assert b._loop.fast_ticks >= n - 2
    assert max(fast['truth']) < 5e-3 * 1.05              # the issue 6 overshoot bound


def test_bench_batch_component_replay_matches_the_stepper_layouts():
    """scripts/bench batch replays a recorded run through each compiled stepper alone; it
    unpacks the steppers' array tuples itself, so a layout change must keep it running."""
    from eha_ros.bench import batch as bb
    loop, refs, loads = bb.build(bb.scenario(0.2))
    rec = loop.run(refs, loads)
    out = bb.components(rec, refs, loads, repeats=1)
    assert sorted(out) == sorted(f'batch_component_{c}_us_per_tick' for c in
                                 ('plant', 'estimator', 'controller', 'switch_manager'))
    assert all(0 < v < 1e4 for v in out.values()), out


def test_compiled_ticks_allocate_nothing():
    """Issue 46, no per-tick allocation: the compiled closed loop (plant, estimator, controller,
    switch manager) allocates per run and per segment (set-up, events, a noise block every
    1024 ticks), never per tick. Counted by numba's runtime: 2000 more ticks with the same
    events cost at most a few segments' allocations (before: 5.1 per tick, the plant's state
    backup and np.linalg.inv's copies in the estimator's update)."""
    from numba.core.runtime import _nrt_python, rtsys
    from eha_ros.bench import batch as bb
    was = _nrt_python.memsys_stats_enabled()
    _nrt_python.memsys_enable_stats()
    try:
        counts = {}
        for duration in (2.0, 4.0):
            loop, refs, loads = bb.build(bb.scenario(duration))
            loop.run(refs[:1], loads[:1])                 # compiled / loaded, started
            before = rtsys.get_allocation_stats().alloc
            loop.run(refs[1:], loads[1:], k0=1)
            counts[duration] = (rtsys.get_allocation_stats().alloc - before, loop.segments,
                                loop.fast_ticks)
    finally:
        if not was:
            _nrt_python.memsys_disable_stats()
    (a2, s2, f2), (a4, s4, f4) = counts[2.0], counts[4.0]
    assert f4 - f2 > 1900                                  # the extra ticks ran compiled
    assert a4 - a2 <= 40 * max(s4 - s2, 1), counts         # per segment, not per tick
