"""Closed position loop on the nonlinear simulated bench over DDS: plant_sim, estimator and
controller as separate processes; the test publishes references and loads and reads
/eha/sim/truth (matched by plant tick). The control figures run in lock-step (the plant steps
when command(k) arrived), so they measure the loop, not the machine's CPU; lost ticks are a
real-time figure. The 1 mm frequency response (bandwidth >= 7 Hz) is measured by
tests/test_sweep_node.py on the same stack."""

import numpy as np
import pytest

from eha_ros.stack import Stack
import probes
from ros_util import STEP_STEADY_LIMIT, wait_for, wait_matched

pytestmark = pytest.mark.ros


def run_stack(lockstep):
    st = Stack(['plant_sim', 'estimator', 'controller'], lockstep=lockstep).start()
    yield st
    for name, (code, err) in st.stop().items():
        assert 'Traceback' not in err, (name, err)


@pytest.fixture(scope='module')
def stack():
    yield from run_stack(lockstep=True)


class Bench(probes.Probe):
    def __init__(self, node):
        from eha_msgs.msg import ExternalLoad, PlantTruth, PositionReference
        super().__init__(node, diagnostics=10)
        self.truth = self.by_seq(PlantTruth, '/eha/sim/truth', 1000,
                                 lambda m: (m.position, m.pressure_a - m.pressure_b))
        self.ref = node.create_publisher(PositionReference, '/eha/reference', 10)
        self.load = node.create_publisher(ExternalLoad, '/eha/sim/load_force', 10)
        self.Ref, self.Load = PositionReference, ExternalLoad

    @property
    def diags(self):
        return [s.values for s in self.diagnostics.all('plant_sim', prefix=True)]

    @property
    def seq(self):
        return max(self.truth) if self.truth else 0

    def wait_ticks(self, n, timeout=60):
        target = self.seq + n
        self.wait(lambda: self.seq >= target, timeout, 'plant stalled')

    def moved_at(self, k0, tol=5e-5):
        """The first plant tick after ``k0`` whose position left that at ``k0`` by more than
        ``tol`` (the reference arrived), or None."""
        seqs = [k for k in sorted(self.truth) if k > k0]
        x0 = self.truth[k0][0] if k0 in self.truth else self.truth[seqs[0]][0] if seqs else 0.0
        return next((k for k in seqs if abs(self.truth[k][0] - x0) > tol), None)

    def positions(self, k0, k1):
        return np.array([self.truth[k][0] for k in range(k0, k1) if k in self.truth])

    def goto(self, position, settle_ticks=1500):
        self.ref.publish(self.Ref(position=position))
        self.wait_ticks(settle_ticks)


@pytest.fixture
def bench(stack, ros_node):
    b = Bench(ros_node)
    assert wait_for(lambda: len(b.truth) > 500, 60), 'no truth from plant_sim'
    wait_matched(b.ref, b.load)
    return b


def test_5mm_step(bench):
    bench.goto(0.0)
    k0 = bench.seq
    bench.ref.publish(bench.Ref(position=0.005))
    # in plant ticks the reference arrives when DDS delivers it (late on a loaded machine):
    # 1.5 s of ticks from the first motion, not from the publish
    bench.wait(lambda: bench.moved_at(k0) is not None, 60, 'the step never moved the piston')
    k1 = bench.moved_at(k0)
    bench.wait(lambda: bench.seq >= k1 + 1500, 60, 'plant stalled')
    seqs = [k for k in sorted(bench.truth) if k >= k1]
    x, t = np.array([bench.truth[k][0] for k in seqs]), (np.array(seqs) - k1) * 1e-3
    final = np.mean(x[(t > 1.0) & (t < 1.4)])
    overshoot = (x.max() - 0.005) / 0.005
    outside = np.nonzero(np.abs(x - 0.005) > 0.02 * 0.005)[0]
    settle = t[outside[-1]] if outside.size else 0.0
    print(f'5 mm step: overshoot {100 * overshoot:.2f} %, 2 % settling {settle:.3f} s, '
          f'steady error {abs(final - 0.005) * 1e6:.1f} um (issue 42: 20 um, '
          f'{"met" if abs(final - 0.005) <= 20e-6 else "not met"})')
    assert overshoot <= 0.05
    assert settle <= 0.3
    assert abs(final - 0.005) <= STEP_STEADY_LIMIT


def test_23kN_static_load(bench):
    bench.goto(0.0, 1000)
    bench.load.publish(bench.Load(force=23e3))
    bench.wait_ticks(8000)                  # the loop's slowest closed-loop pole is ~0.5 rad/s
    k = bench.seq
    x = bench.positions(k - 500, k)
    pd = np.array([bench.truth[j][1] for j in range(k - 500, k) if j in bench.truth])
    print(f'23 kN: position error {np.mean(np.abs(x)) * 1e6:.1f} um (max {np.max(np.abs(x)) * 1e6:.1f}),'
          f' p_A - p_B {np.mean(pd) / 1e5:.1f} bar')
    bench.load.publish(bench.Load(force=0.0))
    assert np.mean(np.abs(x)) <= 50e-6
    assert np.mean(pd) == pytest.approx(23e3 / 2.572e-3, rel=0.05)     # the load is carried

