"""Diagnostics readers beside the loop thread (nodes/diag.py reader): in a composed process
the diagnostics timers run without the process lock, beside the loop thread. A Python loop
over the loop supervisor's saturation deque there raised 'deque mutated during iteration' and
ended eha_loop; the supervisor's figures are now kept as running counts."""
import sys
import threading

from eha_ros.core.loop.supervisor import LoopSupervisor, SupervisorParams
from eha_ros.core.redundancy.params import SCHEMA


def test_supervisor_values_read_beside_the_commanding_loop_thread():
    sup = LoopSupervisor(SupervisorParams.from_params(SCHEMA.defaults()))
    limit = sup.p.saturation * sup.p.omega_max
    stop, errors = threading.Event(), []

    def loop():                  # the loop thread: one command a "tick", half of them saturated
        seq = 0
        while not stop.is_set():
            sup.state(seq, seq * 1e-3)
            sup.command(seq, 2 * limit if seq % 2 else 0.0, seq * 1e-3)
            seq += 1
    old = sys.getswitchinterval()
    sys.setswitchinterval(1e-5)          # switch threads far more often than by default
    t = threading.Thread(target=loop)
    t.start()
    try:
        for _ in range(3000):
            try:
                values = sup.values()                # what publish_supervisor reads
            except RuntimeError as err:
                errors.append(err)
                break
    finally:
        stop.set()
        t.join()
        sys.setswitchinterval(old)
    assert not errors, errors
    # half the commands saturated; a read between a command's count and the window's oldest
    # one leaving it may see one saturated command more: 0.5 + 1/n, rounded to 4 digits
    assert 0.0 <= values['saturated_share'] <= round(0.5 + 1.0 / sup.n, 4)
