"""No compile on the first run (issue 45): scripts/setup compiles every numba kernel into the
on-disk cache with eha_ros.tools.warm_kernels; a fresh process then loads them all."""
import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def warm():
    res = subprocess.run([sys.executable, '-m', 'eha_ros.tools.warm_kernels'], cwd=ROOT,
                         capture_output=True, text=True, timeout=1800)
    assert res.returncode == 0, res.stderr[-2000:]
    return res.stdout


def test_a_second_process_compiles_nothing():
    # the first call compiles what a code change left uncached (nothing after scripts/setup);
    # the second, a fresh process, must find every kernel of every warmed path in the cache
    first = warm()
    second = warm()
    print(first, second, sep='\n')
    paths = re.findall(r'warm_kernels: ([a-z -]+): (\d+) compiled', second)
    assert [p for p, _ in paths] == ['closed loop', 'real-time branches', 'switch manager node',
                                     'identification']
    assert all(n == '0' for _, n in paths), second
    assert 'warm_kernels: 0 kernels compiled into the cache' in second
