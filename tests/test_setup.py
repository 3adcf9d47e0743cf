"""scripts/setup is idempotent: a second run with nothing changed is a quick no-op."""
import os
import re
import subprocess
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SETUP = os.path.join(ROOT, 'scripts', 'setup')


def run_setup(*args, env=None):
    full = dict(os.environ, **(env or {}))
    t0 = time.monotonic()
    res = subprocess.run([SETUP, *args], capture_output=True, text=True, env=full, timeout=1800)
    return res, time.monotonic() - t0


def test_second_run_is_a_quick_no_op():
    first, _ = run_setup()
    assert first.returncode == 0, first.stderr
    second, wall = run_setup()
    assert second.returncode == 0, second.stderr
    for step in ('deps', 'cmake-fix', 'eha_msgs', 'eha_ros', 'kernels'):
        assert f'{step}: up to date' in second.stdout, second.stdout
    assert 'installing' not in second.stdout and 'building' not in second.stdout
    reported = float(re.search(r'ready in ([0-9.]+) s', second.stdout).group(1))
    print(f'second setup run: {wall:.2f} s wall, {reported:.2f} s reported')
    assert wall < 30.0


def test_failed_step_is_one_line_naming_the_step():
    res, _ = run_setup(env={'EHA_PYTHON': 'python3.11-does-not-exist'})
    assert res.returncode == 1
    lines = res.stderr.strip().splitlines()
    assert lines == ["setup: step 'python' failed: interpreter 'python3.11-does-not-exist' not "
                     "found; install CPython 3.11 or set EHA_PYTHON"], res.stderr


def test_unknown_option_is_refused():
    res, _ = run_setup('--fast')
    assert res.returncode == 2 and 'unknown option' in res.stderr
