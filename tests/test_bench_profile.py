"""scripts/bench profile's accounting (eha_ros/bench/profile.py): each sampled stack is charged
to the innermost frame that names a stage, and samples become microseconds per tick."""
import pytest

from eha_ros.bench import profile as P

LOOP = 'Thread._bootstrap (threading.py:1002);PlantSide.realtime_loop ' \
       '(eha_ros/nodes/plant_side.py:415);PlantSide.tick (eha_ros/nodes/plant_side.py:440)'
RAW = '\n'.join([
    # the estimator's kernel, called through the in-process delivery: the estimator
    LOOP + ';LocalPublisher.publish (eha_ros/nodes/compose.py:93);Bus.guard.<locals>.guarded '
    '(eha_ros/nodes/compose.py:58);EstimatorNode.on_state (eha_ros/nodes/estimator.py:94);'
    'Estimator.update (eha_ros/core/estimator/estimator.py:310) 300',
    # a message field set inside the plant side: message building
    LOOP + ';PlantSide.publish_state (eha_ros/nodes/plant_side.py:522);ActuatorState.position '
    '(eha_msgs/msg/_actuator_state.py:200) 100',
    # the delivery itself (the lock): in-process delivery
    LOOP + ';LocalPublisher.publish (eha_ros/nodes/compose.py:93);Bus.guard.<locals>.guarded '
    '(eha_ros/nodes/compose.py:58) 50',
    LOOP + ';EhaPlant.measure (eha_ros/core/plant/model.py:206) 40',
    'spin (eha_ros/nodes/common.py:117);spin_once (rclpy/executors.py:800) 10',
    'garbage',
])


def test_samples_are_charged_to_the_innermost_stage_and_scaled_per_tick():
    wall = 500 / P.RATE                     # 500 samples' time: one sample = 2 us per tick
    b = P.breakdown(RAW, wall=wall)
    us = 1e6 / P.RATE / wall / P.TICK_HZ
    assert us == pytest.approx(2.0)
    st = b['stages_us_per_tick']
    assert st == pytest.approx({'estimator (core)': 300 * us,
                                'message fields (generated classes)': 100 * us,
                                'in-process delivery (nodes/compose.py)': 50 * us,
                                'plant model: outputs (measure, truth)': 40 * us,
                                'executor, timers (rclpy)': 10 * us})
    assert b['sampled_us_per_tick'] == pytest.approx(500 * us)
    assert sum(b['stage_share'].values()) == pytest.approx(1.0)
    own = b['stage_top_frames_us_per_tick']['message fields (generated classes)']
    assert list(own) == ['PlantSide.publish_state (eha_ros/nodes/plant_side.py:522)']


def test_only_the_samples_of_one_thread():
    b = P.breakdown(RAW, wall=1.0, only='PlantSide.realtime_loop ')
    assert 'executor, timers (rclpy)' not in b['stages_us_per_tick']
    assert b['stage_share']['estimator (core)'] == pytest.approx(300 / 490)


def test_bench_tick_runs_the_composed_tick_back_to_back():
    """scripts/bench tick's child: eha_loop's nodes, the plant side ticking back to back."""
    from eha_ros.bench import tick
    r = tick._run_child(1000)
    print(r)
    assert r['ticks'] == 1000
    assert 0 < r['us_per_tick_best'] <= r['us_per_tick_median'] < 5000
    assert r['cpu_us_per_tick'] > 0


def _fake_children(monkeypatch, raw_text):
    """bench tick's two children replaced: the tick figures, and py-spy's raw file (the loop
    thread's entry is the child's back-to-back loop)."""
    from eha_ros.bench import tick
    raw_text = raw_text.replace('PlantSide.realtime_loop ', tick.LOOP_THREAD)

    def child(ticks, spy=None, raw=None):
        if raw is not None:
            with open(raw, 'w') as fh:
                fh.write(raw_text)
        return {'us_per_tick_best': 50.0, 'us_per_tick_median': 55.0, 'cpu_us_per_tick': 48.0,
                'ticks': ticks}
    monkeypatch.setattr(tick, '_run_child', child)
    monkeypatch.setattr(tick, 'py_spy', lambda: 'py-spy')
    return tick


def test_bench_tick_writes_no_breakdown_from_a_handful_of_samples(monkeypatch, capsys):
    """py-spy falls behind on a busy machine (30 samples in a 6000-tick run beside a
    campaign): the stage figures are then left out and said so, the tick figures stay."""
    tick = _fake_children(monkeypatch, RAW.replace(' 300', ' 3').replace(' 100', ' 1'))
    r = tick.run(None)
    assert r['profile_samples'] == 3 + 1 + 50 + 40
    assert 'stages_us_per_tick' not in r and r['us_per_tick_best'] == 50.0
    assert 'no per-stage figures written' in capsys.readouterr().err


def test_bench_tick_charges_the_loop_threads_samples_to_the_best_block(monkeypatch):
    """Enough samples: each stage is its share of the loop thread's samples x the best block
    (the executor's thread is not the loop's)."""
    many = RAW.replace(' 300', ' 3000').replace(' 100', ' 1000').replace(' 50\n', ' 500\n')
    tick = _fake_children(monkeypatch, many.replace(' 40\n', ' 400\n'))
    r = tick.run(None)
    assert r['profile_samples'] == 3000 + 1000 + 500 + 400
    assert r['stages_us_per_tick']['estimator (core)'] == pytest.approx(50.0 * 3000 / 4900)
    assert sum(r['stages_us_per_tick'].values()) == pytest.approx(50.0)
