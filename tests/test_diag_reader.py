"""Diagnostics readers beside the loop thread (nodes/diag.py reader): a composed process's
diagnostics timer reads the dicts and deques the loop thread changes; unguarded, that raised
'deque mutated during iteration' and ended eha_loop."""
import sys
import threading
import time

from eha_ros.nodes import diag


class FakeNode:
    """What a reader needs of a node: the callback lock and state the 'loop' changes."""
    callback_lock = threading.RLock()

    def __init__(self):
        self.counts = {i: i for i in range(2000)}

    @diag.reader
    def publish_diagnostics(self):
        keys = [k for k in self.counts]                   # Python-level iteration
        diag.publish(self, None, 'loop', {'keys': len(keys)})


def test_reader_gathers_under_the_lock_and_publishes_after_it(monkeypatch):
    node, sent, stop = FakeNode(), [], threading.Event()

    def send(n, pub, name, values, level, message):
        # the publish runs with the lock free: another thread can take it at once
        got = []

        def take():
            got.append(n.callback_lock.acquire(timeout=1.0))
            if got[0]:
                n.callback_lock.release()
        t = threading.Thread(target=take)
        t.start()
        t.join()
        sent.append((values['keys'], got[0]))
    monkeypatch.setattr(diag, '_send', send)

    def loop():                  # the loop thread: changes the dict under the lock per "tick"
        k = 0
        while not stop.is_set():
            with node.callback_lock:         # a counter appears, or goes
                if k % 2:
                    node.counts.pop(-1)
                else:
                    node.counts[-1] = k
                k += 1
            time.sleep(1e-4)     # between ticks
    old = sys.getswitchinterval()
    sys.setswitchinterval(1e-5)          # switch threads far more often than by default
    t = threading.Thread(target=loop)
    t.start()
    try:
        for _ in range(300):
            node.publish_diagnostics()
    finally:
        stop.set()
        t.join()
        sys.setswitchinterval(old)
    assert len(sent) == 300 and all(free for _, free in sent)
    assert all(n in (2000, 2001) for n, _ in sent), sorted({n for n, _ in sent})

