"""scripts/ads_peer as its own process (real time, with its ROS side) and hardware_bridge over
DDS: /eha/inject_fault served by the peer shows in the bridge's /eha/state; the peer's PLC
heartbeat watchdog; command-line mistakes end in one line."""
import subprocess
import threading

import numpy as np
import pytest

from eha_ros.stack import node_command
from ros_util import ROOT, start_process, stop_process, wait_for
from test_bridge_core import free_port

pytestmark = pytest.mark.ros
PEER = f'{ROOT}/scripts/ads_peer'


def test_help_and_bad_arguments():
    res = subprocess.run([PEER, '--help'], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0 and '--lockstep' in res.stdout and 'inject_fault' in res.stdout
    res = subprocess.run([PEER, '--port', '70000', '--no-ros'], capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 2 and res.stderr.strip() == 'ads_peer: error: --port 70000: ' \
        'expected 1..65535', res.stderr
    res = subprocess.run([PEER, '--symbols', '/nonexistent.yaml', '--no-ros'],
                         capture_output=True, text=True, timeout=60)
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(lines) == 1 and 'no such file' in lines[0], res.stderr


@pytest.fixture(scope='module')
def peer_and_bridge():
    port = free_port()
    peer = start_process([PEER, '--port', str(port)])
    lines = []
    threading.Thread(target=lambda: lines.append(peer.stdout.readline()), daemon=True).start()
    assert wait_for(lambda: lines, 60) and 'inject_fault served' in lines[0], lines
    bridge = start_process(node_command('hardware_bridge', extra=[
        '-p', f'hardware_bridge:ads.tcp_port:={port}',
        '-p', 'hardware_bridge:bridge.startup_discovery:=0.5']))
    yield peer, bridge
    code, out, err = stop_process(bridge)
    assert 'Traceback' not in err, err
    code, out, err = stop_process(peer)
    assert 'Traceback' not in err and code == 0, err
    print(out.strip().splitlines()[-1])
    assert 'heartbeat trips' in out


def test_fault_injected_at_the_peer_shows_in_bridge_state(peer_and_bridge, ros_node):
    from eha_msgs.msg import ActuatorState
    from eha_msgs.srv import InjectFault
    from rclpy.qos import QoSProfile
    states = []
    ros_node.create_subscription(ActuatorState, '/eha/state', states.append, QoSProfile(depth=1000))
    assert wait_for(lambda: len(states) > 300, 60), 'no state from the bridge'
    before = np.median([s.position for s in states[-200:]])
    cli = ros_node.create_client(InjectFault, '/eha/inject_fault')
    assert cli.wait_for_service(timeout_sec=30)
    fut = cli.call_async(InjectFault.Request(fault='msp_bias', channel=0, magnitude=2e-3,
                                             duration=0.0))
    assert wait_for(fut.done, 20) and fut.result().success, fut.result()
    assert '(tick ' in fut.result().message
    n = len(states)
    assert wait_for(lambda: len(states) > n + 300, 30)
    after = np.median([s.position for s in states[-200:]])
    print(f'msp_bias 2 mm at the peer: bridge state position {1e3 * before:.3f} -> '
          f'{1e3 * after:.3f} mm')
    assert abs(after - before - 2e-3) < 2e-4
    fut = cli.call_async(InjectFault.Request(fault='no_such_fault'))
    assert wait_for(fut.done, 20) and not fut.result().success
    assert 'unknown fault' in fut.result().message
