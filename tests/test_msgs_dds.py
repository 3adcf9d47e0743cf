"""Every eha_msgs message and service crosses between two processes over DDS, fields intact."""
import os
import sys

import pytest

from ros_util import MSG_TYPES, fill, start_process, stop_process, wait_for

pytestmark = pytest.mark.ros
PEER = os.path.join(os.path.dirname(os.path.abspath(__file__)), 'peers', 'msg_peer.py')


@pytest.fixture(scope='module')
def peer():
    proc = start_process([sys.executable, PEER])
    yield proc
    code, out, err = stop_process(proc)
    assert 'Traceback' not in err, err


def test_every_message_arrives_intact(peer, ros_node):
    import eha_msgs.msg as M
    got = {}
    for t in MSG_TYPES:
        ros_node.create_subscription(getattr(M, t), f'/test/{t}',
                                     lambda m, t=t: got.setdefault(t, m), 10)
    assert wait_for(lambda: len(got) == len(MSG_TYPES), 30), \
        f'missing: {sorted(set(MSG_TYPES) - set(got))}'
    for t in MSG_TYPES:
        expected = fill(getattr(M, t)())
        assert got[t] == expected, f'{t}: {got[t]} != {expected}'
        # the sample is not the default message, so equality means the fields crossed
        assert got[t] != getattr(M, t)()


@pytest.mark.parametrize('srv', ['switch_channel', 'inject_fault'])
def test_every_service_round_trips(peer, ros_node, srv):
    from eha_msgs.srv import InjectFault, SwitchChannel
    if srv == 'switch_channel':
        client = ros_node.create_client(SwitchChannel, '/test/switch_channel')
        req = SwitchChannel.Request(channel=1, reason='operator test')
        expect = (True, 'switch:1:operator test')
    else:
        client = ros_node.create_client(InjectFault, '/test/inject_fault')
        req = InjectFault.Request(fault='msp_bias', channel=1, magnitude=1e-3, duration=0.25)
        expect = (True, 'msp_bias:1:0.001:0.25')
    assert client.wait_for_service(timeout_sec=30)
    future = client.call_async(req)
    assert wait_for(future.done, 10)
    resp = future.result()
    assert (resp.success, resp.message) == expect
