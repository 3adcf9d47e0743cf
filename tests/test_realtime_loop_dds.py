"""The closed loop in real time over DDS (plant_sim, estimator, controller as processes at 1 kHz):
lost ticks. In a module of its own so that no other stack shares the topics."""
import time

import pytest

from test_closed_loop_dds import Bench, run_stack
from ros_util import wait_for

pytestmark = pytest.mark.ros


@pytest.fixture(scope='module')
def realtime_stack():
    yield from run_stack(lockstep=False)


@pytest.mark.xfail(strict=True, reason='measured on this 2-core machine: the real-time DDS loop '
                   'misses the 1 ms deadline on about half the ticks; each 1 kHz message costs '
                   '70-250 us of CPU here (issue 10: structure of the real-time stack)')
def test_lost_ticks_over_30s(realtime_stack, ros_node):
    """A tick is lost when the plant steps without the command answering its last state."""
    bench = Bench(ros_node)
    assert wait_for(lambda: bench.diags, 20)
    d0 = bench.diags[-1]
    time.sleep(30.0)
    n = len(bench.diags)
    assert wait_for(lambda: len(bench.diags) > n, 5)
    d1 = bench.diags[-1]
    ticks = int(d1['ticks']) - int(d0['ticks'])
    lost = int(d1.get('commands_not_for_previous_tick', 0)) - \
        int(d0.get('commands_not_for_previous_tick', 0))
    print(f'lost ticks: {lost} of {ticks} ({100 * lost / ticks:.3f} %)')
    assert ticks > 25000
    assert lost <= 0.001 * ticks
