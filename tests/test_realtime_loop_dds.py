"""The closed loop in real time at 1 kHz, as scripts/run_stack runs it (plant_sim, estimator,
controller composed in eha_loop; this test over DDS): lost ticks over 30 s. In a module of its
own so that no other stack shares the topics. The issue's 0.1 % goal on a quiet machine is
measured by `scripts/bench stack` (out/bench/stack.json); this test bounds it at 1 % so that a
loaded CI machine does not fail it, while any structural regression does (the same nodes as
separate processes lose about 97 % of the ticks here)."""
import time

import pytest

from eha_ros.stack import Stack
from test_closed_loop_dds import Bench
from ros_util import wait_for

pytestmark = pytest.mark.ros


@pytest.fixture(scope='module')
def realtime_stack():
    st = Stack(['plant_sim', 'estimator', 'controller'], composed=True).start()
    yield st
    for name, (code, err) in st.stop().items():
        assert 'Traceback' not in err, (name, err)


def test_lost_ticks_over_30s(realtime_stack, ros_node):
    """A tick is lost when the plant steps without the command answering its last state."""
    bench = Bench(ros_node)
    assert wait_for(lambda: bench.diags, 60)
    d0 = bench.diags[-1]
    time.sleep(30.0)
    n = len(bench.diags)
    assert wait_for(lambda: len(bench.diags) > n, 5)
    d1 = bench.diags[-1]
    ticks = int(d1['ticks']) - int(d0['ticks'])
    lost = int(d1.get('commands_not_for_previous_tick', 0)) - \
        int(d0.get('commands_not_for_previous_tick', 0))
    print(f'lost ticks: {lost} of {ticks} ({100 * lost / ticks:.3f} %), latency p99 '
          f'{float(d1["latency_p99_s"]) * 1e3:.2f} ms')
    assert ticks > 25000
    assert lost <= 0.01 * ticks
