"""Installed like a ROS package (issue 45): `colcon build` of src/ (eha_msgs ament_cmake,
eha_ros ament_python) into a temporary workspace, with the ament of the venv as the underlay.
Then, from a folder outside the repository and with the install's setup.bash sourced (its
site-packages first on PYTHONPATH, EHA_CONFIG_DIR unset), plant_sim is found the way
`ros2 run eha_ros plant_sim` finds it (<prefix of eha_ros in the ament index>/lib/eha_ros),
reads its params files from the installed share/eha_ros/config, and streams /eha/state over
DDS at 1 kHz."""
import glob
import json
import os
import re
import subprocess
import time

import numpy as np
import pytest

from eha_ros.stack import spawn
from ros_util import ROOT, VENV_BIN, stop_process, wait_for

VENV = os.path.dirname(VENV_BIN)
VPY = os.path.join(VENV_BIN, 'python')
COLCON = os.path.join(VENV_BIN, 'colcon')
PACKAGES = ['eha_msgs', 'eha_ros']

# run in the installed environment: what it imports from where, and the config folder it finds
PROBE = '''
import json, sys
import eha_msgs.msg, eha_ros
from eha_ros.core.config.params import default_config_dir
from eha_ros.core.config.registry import NODE_FILES
mods = [getattr(m, '__file__', None) or '' for m in list(sys.modules.values())]
print(json.dumps({'eha_ros': eha_ros.__file__, 'eha_msgs': eha_msgs.msg.__file__,
                  'config_dir': default_config_dir(), 'files': NODE_FILES['plant_sim'],
                  'from_checkout': sorted(m for m in mods if m.startswith(sys.argv[1]))}))
'''


def build_env() -> dict:
    """The venv as the ROS underlay: its ament (CMake and the index) and its interpreter."""
    env = {k: v for k, v in os.environ.items() if k not in ('EHA_CONFIG_DIR', 'PYTHONPATH')}
    env.update(AMENT_PREFIX_PATH=VENV, CMAKE_PREFIX_PATH=VENV,
               PATH=VENV_BIN + os.pathsep + env.get('PATH', ''))
    # colcon gives make -jN -lN unless MAKEFLAGS says otherwise: with -l a machine loaded by
    # other work compiles one file at a time (240 s instead of 40 s seen here)
    env.setdefault('MAKEFLAGS', f'-j{os.cpu_count() or 2}')
    return env


def sourced(setup_bash: str, env: dict, cwd: str) -> dict:
    """The environment after `source install/setup.bash` on top of ``env``."""
    res = subprocess.run(['bash', '-c', f'source "{setup_bash}" && env -0'], env=env, cwd=cwd,
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, f'source {setup_bash} failed: {res.stderr[-2000:]}'
    return dict(line.split('=', 1) for line in res.stdout.split('\0') if '=' in line)


def ros2_run_path(package: str, executable: str, ament_prefix_path: str, monkeypatch) -> str:
    """What `ros2 run` does (ros2run.api.get_executable_path): the package's prefix from the
    ament index, then <prefix>/lib/<package>/<executable>, which must be executable."""
    from ament_index_python.packages import get_package_prefix
    with monkeypatch.context() as m:
        m.setenv('AMENT_PREFIX_PATH', ament_prefix_path)
        prefix = get_package_prefix(package)
    path = os.path.join(prefix, 'lib', package, executable)
    assert os.path.isfile(path) and os.access(path, os.X_OK), f'{path}: no executable'
    return path


def files_under(folder: str) -> set:
    return {os.path.relpath(os.path.join(d, f), folder)
            for d, _, names in os.walk(folder) for f in names if not f.startswith('.')}


def test_config_dir_order_env_then_checkout_then_ament_index(tmp_path, monkeypatch):
    """default_config_dir(): $EHA_CONFIG_DIR, else the checkout's config/, else
    share/eha_ros/config of the ament index, else one line naming the three places."""
    from eha_ros.core.config import params
    monkeypatch.delenv('EHA_CONFIG_DIR', raising=False)
    monkeypatch.delenv('AMENT_PREFIX_PATH', raising=False)
    monkeypatch.chdir(tmp_path)
    (tmp_path / 'config').mkdir()             # a ./config of the current folder is never used
    assert params.default_config_dir() == os.path.join(ROOT, 'config')
    monkeypatch.setenv('EHA_CONFIG_DIR', str(tmp_path / 'config'))
    assert params.default_config_dir() == str(tmp_path / 'config')
    monkeypatch.setenv('EHA_CONFIG_DIR', str(tmp_path / 'nowhere'))
    with pytest.raises(params.ParamError, match=r'^EHA_CONFIG_DIR=\S+nowhere: no such folder'):
        params.default_config_dir()
    monkeypatch.delenv('EHA_CONFIG_DIR')
    # installed: no checkout around this module
    monkeypatch.setattr(params, 'checkout_config_dir', lambda: str(tmp_path / 'lib' / 'config'))
    with pytest.raises(params.ParamError) as err:
        params.default_config_dir()
    text = str(err.value)
    print(text)
    assert '\n' not in text and 'EHA_CONFIG_DIR is not set' in text
    assert str(tmp_path / 'lib' / 'config') in text and 'AMENT_PREFIX_PATH unset' in text
    prefix = tmp_path / 'prefix'
    (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages').mkdir(parents=True)
    (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'eha_ros').touch()
    monkeypatch.setenv('AMENT_PREFIX_PATH', f'{VENV}{os.pathsep}{prefix}')
    share = prefix / 'share' / 'eha_ros' / 'config'
    with pytest.raises(params.ParamError, match=re.escape(str(share))):
        params.default_config_dir()            # indexed, but installed without config/
    share.mkdir(parents=True)
    assert params.default_config_dir() == str(share)


@pytest.mark.ros
def test_colcon_build_installs_a_node_that_runs_from_the_install(tmp_path, ros_node,
                                                                 monkeypatch):
    assert os.access(COLCON, os.X_OK), f'{COLCON} missing: run scripts/setup (requirements.txt)'
    ws, work = tmp_path / 'ws', tmp_path / 'elsewhere'
    ws.mkdir()
    work.mkdir()
    install = ws / 'install'
    env = build_env()
    cmd = [COLCON, '--log-base', str(ws / 'log'), 'build', '--base-paths',
           os.path.join(ROOT, 'src'), '--build-base', str(ws / 'build'),
           '--install-base', str(install), '--event-handlers', 'desktop_notification-',
           '--cmake-args', f'-DPython3_EXECUTABLE={VPY}', '-DBUILD_TESTING=OFF']
    t0 = time.monotonic()
    res = subprocess.run(cmd, env=env, cwd=ws, capture_output=True, text=True, timeout=480)
    build_s = time.monotonic() - t0
    assert res.returncode == 0, f'colcon build failed:\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}'
    finished = dict(re.findall(r'^Finished <<< (\S+) \[([^]]+)\]', res.stdout, re.M))
    built = sorted(finished)
    print(f'colcon build: {", ".join(f"{p} [{t}]" for p, t in finished.items())}, '
          f'{build_s:.1f} s in all ({install})')
    assert built == PACKAGES, res.stdout

    # every file of config/ (params files, campaign scenarios, the Foxglove layout) installed
    share_config = install / 'eha_ros' / 'share' / 'eha_ros' / 'config'
    repo_files = files_under(os.path.join(ROOT, 'config'))
    assert {'plant.yaml', 'campaigns/step.yaml', 'foxglove/eha_layout.json'} <= repo_files
    assert files_under(str(share_config)) == repo_files

    # the installed environment, as a user has it after sourcing the install (the venv's
    # ament as the underlay), from a folder outside the repository
    run_env = sourced(str(install / 'setup.bash'), env, str(work))
    run_env.pop('EHA_CONFIG_DIR', None)
    pythonpath = [p for p in run_env.get('PYTHONPATH', '').split(os.pathsep) if p]
    site = sorted(glob.glob(str(install / '*' / 'lib' / 'python3*' / 'site-packages')))
    assert [os.path.dirname(os.path.dirname(os.path.dirname(p))) for p in site] == \
        [str(install / p) for p in PACKAGES]
    assert set(site) <= set(pythonpath), pythonpath
    assert not any(p.startswith(ROOT) for p in pythonpath), pythonpath

    exe = ros2_run_path('eha_ros', 'plant_sim', run_env['AMENT_PREFIX_PATH'], monkeypatch)
    print(f'ros2 run eha_ros plant_sim -> {exe}')
    assert exe == str(install / 'eha_ros' / 'lib' / 'eha_ros' / 'plant_sim')

    # the executable's interpreter in that environment: everything from the install, nothing
    # of the checkout (the venv's editable eha_ros comes after PYTHONPATH), config/ from share
    interpreter = open(exe, encoding='utf-8').readline()[2:].strip()
    res = subprocess.run([interpreter, '-c', PROBE, os.path.join(ROOT, 'src')], env=run_env,
                         cwd=work, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-3000:]
    found = json.loads(res.stdout.strip().splitlines()[-1])
    assert found['eha_ros'].startswith(str(install / 'eha_ros')), found
    assert found['eha_msgs'].startswith(str(install / 'eha_msgs')), found
    assert found['from_checkout'] == [], found
    assert found['config_dir'] == str(share_config), found
    print(f'config folder (default_config_dir() in the installed environment): '
          f'{found["config_dir"]}; params files {", ".join(found["files"])}')

    # plant_sim as a separate process, its params files from the installed config folder
    args = [exe, '--ros-args']
    for f in found['files']:
        args += ['--params-file', os.path.join(found['config_dir'], f)]
    from eha_msgs.msg import ActuatorState
    from rclpy.qos import QoSProfile
    states = []
    ros_node.create_subscription(ActuatorState, '/eha/state', states.append,
                                 QoSProfile(depth=1000))
    proc = spawn(args, env=run_env, cwd=work, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                 text=True)
    try:
        # discovery and start-up (numba kernels, first run from a fresh install) may take a
        # while on a loaded machine; then a window of 3000 ticks of the plant's own time
        assert wait_for(lambda: states or proc.poll() is not None, 240), 'no /eha/state'
        assert proc.poll() is None, 'plant_sim ended'
        first = len(states)
        assert wait_for(lambda: len(states) >= first + 3000 or proc.poll() is not None, 120), \
            f'/eha/state stalled after {len(states)} messages'
        window = states[first:first + 3000]
    finally:
        code, out, err = stop_process(proc)
    seqs = np.array([s.seq for s in window])
    stamps = np.array([s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec for s in window])
    # the rate by the plant's own stamps: its tick is 1 ms (median); over the window a loop
    # that a loaded machine (other tests, a build) starves now and then falls a little behind
    rate = (seqs[-1] - seqs[0]) / (stamps[-1] - stamps[0])
    tick = np.median(np.diff(stamps) / np.diff(seqs))
    received = len(seqs) / (seqs[-1] - seqs[0] + 1)
    print(f'/eha/state: {len(states)} messages seen, window of {len(seqs)}: seq {seqs[0]} -> '
          f'{seqs[-1]}, {rate:.1f} Hz over the window, median tick {1e3 * tick:.3f} ms, '
          f'received {100 * received:.2f} %; plant_sim exit {code}')
    assert np.all(np.diff(seqs) >= 1), 'seq not increasing'
    assert 0.95e-3 <= tick <= 1.05e-3
    assert 900 <= rate <= 1020
    assert received >= 0.99
    assert code == 0, err[-3000:]
