"""live node: the stack over the Foxglove WebSocket protocol, checked with an independent
client (eha_ros/tools/ws_client.py on `websockets`, subprotocol foxglove.websocket.v1)
against a simultaneous DDS subscription, by seq."""
import os
import socket
import subprocess
import sys

import pytest

from eha_ros.core.io.ws_subprotocol import CURRENT, LEGACY, rename_request, rename_response
from ros_util import free_port, wait_for

NODES = ['plant_sim', 'estimator', 'controller', 'switch_manager']


def live_cmd(*params):
    exe = os.path.join(os.path.dirname(sys.executable), 'live')
    args = [exe, '--ros-args', '--params-file', 'config/live.yaml']
    for p in params:
        args += ['-p', p]
    return args


# ---- the subprotocol relay (pure) -------------------------------------------------------

def test_legacy_subprotocol_is_renamed_both_ways():
    req = (b'GET / HTTP/1.1\r\nHost: x\r\nSec-WebSocket-Protocol: ' + LEGACY +
           b'\r\nSec-WebSocket-Key: abc\r\n\r\n')
    out, back = rename_request(req)
    assert back and b'Sec-WebSocket-Protocol: ' + CURRENT + b'\r\n' in out
    assert out.replace(CURRENT, LEGACY) == req
    ans = (b'HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: ' + CURRENT +
           b'\r\n\r\n')
    assert rename_response(ans) == ans.replace(CURRENT, LEGACY)
    # a client that offers the current name (or both) passes unchanged
    for offer in (CURRENT, LEGACY + b', ' + CURRENT):
        req2 = b'GET / HTTP/1.1\r\nSec-WebSocket-Protocol: ' + offer + b'\r\n\r\n'
        assert rename_request(req2) == (req2, False)
    assert rename_request(b'GET / HTTP/1.1\r\n\r\n') == (b'GET / HTTP/1.1\r\n\r\n', False)


def test_relay_renames_the_handshake_and_copies_every_byte_in_order():
    """SubprotocolRelay against a plain TCP server standing in for the SDK: the request reaches
    it with foxglove.sdk.v1, the answer comes back with the legacy name, then 200 kB in
    irregular pieces cross each way unchanged and in order (batched copies lose nothing)."""
    import threading
    from eha_ros.core.io.ws_subprotocol import SubprotocolRelay
    srv = socket.create_server(('127.0.0.1', 0))
    seen = {}
    payload = bytes(range(256)) * 800

    def server():
        conn, _ = srv.accept()
        head = b''
        while b'\r\n\r\n' not in head:
            head += conn.recv(4096)
        seen['head'] = head
        conn.sendall(b'HTTP/1.1 101 Switching Protocols\r\nSec-WebSocket-Protocol: ' +
                     CURRENT + b'\r\n\r\n')
        for i in range(0, len(payload), 777):
            conn.sendall(payload[i:i + 777])
        got = b''
        while len(got) < len(payload):
            got += conn.recv(65536)
        seen['up'] = got
        conn.close()
    t = threading.Thread(target=server, daemon=True)
    t.start()
    relay = SubprotocolRelay('127.0.0.1', 0, srv.getsockname()[1], period=0.002)
    try:
        c = socket.create_connection(('127.0.0.1', relay.port), timeout=10)
        c.sendall(b'GET / HTTP/1.1\r\nSec-WebSocket-Protocol: ' + LEGACY + b'\r\n\r\n')
        data = b''
        while len(data) < len(payload) or b'\r\n\r\n' not in data:
            data += c.recv(65536)
        answer, _, body = data.partition(b'\r\n\r\n')
        assert LEGACY in answer and CURRENT not in answer
        while len(body) < len(payload):
            body += c.recv(65536)
        assert body == payload
        c.sendall(payload)
        t.join(10)
        assert CURRENT in seen['head'] and LEGACY not in seen['head']
        assert seen['up'] == payload
        c.close()
    finally:
        relay.close()
        srv.close()


def test_eha_loop_guest_reads_only_its_own_sections():
    """live in eha_loop gets the loop's params files, whose /** sections hold the plant
    parameters: as a guest it takes only what is addressed to it by name."""
    from eha_ros.core.io.live_params import SCHEMA
    from eha_ros.core.config.params import ParamError, load
    files = ['config/plant.yaml', 'config/live.yaml']
    p = load(SCHEMA, files, {'live:live.port': 9, 'plant.sim.Ts': 1e-3}, node='live',
             wildcards=False)
    assert p['live.port'] == 9 and p['live.flush_period'] == 0.02
    with pytest.raises(ParamError, match='unknown parameter'):
        load(SCHEMA, files, node='live')


def test_in_process_subscriber_counts_only_while_it_wants_messages():
    """compose.LocalPublisher: a co-located callback with eha_wanted() False (live without a
    viewer) is not a listener, so the plant does not build its truth message for nobody."""
    from eha_ros.nodes.compose import Bus, LocalPublisher

    class Dds:
        def get_subscription_count(self):
            return 0
    bus = Bus()
    pub = LocalPublisher(bus, '/eha/sim/truth', Dds(), latched=False)
    got = []
    want = [False]

    def live_cb(msg):
        got.append(msg)
    live_cb.eha_wanted = lambda: want[0]
    bus.subscribers['/eha/sim/truth'].append(live_cb)
    assert pub.get_subscription_count() == 0
    want[0] = True
    assert pub.get_subscription_count() == 1
    bus.subscribers['/eha/sim/truth'].append(got.append)      # a plain subscriber always counts
    want[0] = False
    assert pub.get_subscription_count() == 1
    pub.publish('m')
    assert got == ['m', 'm']


def test_decimation_entries():
    from eha_ros.core.config.params import ParamError
    from eha_ros.core.io.live_params import decimation
    assert decimation(['']) == {}
    assert decimation(['/eha/sim/truth:10', '/diagnostics:2']) == {'/eha/sim/truth': 10,
                                                                   '/diagnostics': 2}
    for bad in ('/eha/state', '/eha/state:0', 'eha/state:3', '/eha/state:x'):
        with pytest.raises(ParamError, match='live.decimation'):
            decimation([bad])


@pytest.mark.parametrize('param, text', [
    ("live:live.decimation:=['/eha/state:0']", "live.decimation: '/eha/state:0'"),
    ('live:live.port:=70000', 'live.port'),
])
def test_bad_parameters_are_one_line(param, text):
    res = subprocess.run(live_cmd(param), capture_output=True, text=True, timeout=60,
                         env=dict(os.environ, ROS_DOMAIN_ID='0'))
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(lines) == 1, res.stderr
    assert lines[0].startswith('live: error:') and text in lines[0], lines[0]


def test_port_in_use_is_one_line():
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        s.listen()
        port = s.getsockname()[1]
        res = subprocess.run(live_cmd(f'live:live.port:={port}'), capture_output=True,
                             text=True, timeout=60)
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(lines) == 1, res.stderr
    assert f'cannot serve on 127.0.0.1:{port}' in lines[0]


# ---- the whole stack over DDS and WebSocket ----------------------------------------------

@pytest.mark.parametrize('where', ['in_loop', 'own_process'])
def test_live_view_agrees_with_dds_by_seq(ros_node, tmp_path, where):
    """Real-time composed stack with live inside eha_loop (run_stack --live: the loop topics
    taken in-process) or as its own process next to it (the live executable, DDS); the test
    subscribes over DDS and over the WebSocket at once: every state and estimate both
    received are the same message, field by field (in the loop: encoded by core.io.cdr); the
    truth topic is decimated 1:10; a channel switch requested from the viewer is carried out;
    parameters read back."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rclpy.serialization import deserialize_message

    from eha_msgs.msg import ActuatorState, PlantTruth, PositionEstimate, RedundancyStatus
    from eha_ros.stack import Stack
    from eha_ros.tools.ws_client import SUBPROTOCOL, FoxgloveClient

    port = free_port()
    dds = {'/eha/state': {}, '/eha/estimate': {}}
    redundancy = []
    qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    for topic, cls in (('/eha/state', ActuatorState), ('/eha/estimate', PositionEstimate)):
        ros_node.create_subscription(cls, topic, lambda m, t=topic: dds[t].__setitem__(
            m.seq, m), qos)
    ros_node.create_subscription(RedundancyStatus, '/eha/redundancy',
                                 lambda m: redundancy.append(m.active_channel), 10)
    extra = {'live': ['-p', "live:live.decimation:=['/eha/sim/truth:10']"]}
    if where == 'in_loop':
        st = Stack(NODES, composed=True, live=port, log_dir=str(tmp_path / 'logs'),
                   extra=extra)
    else:
        extra['live'] += ['-p', f'live:live.port:={port}']
        st = Stack(NODES + ['live'], composed=True, log_dir=str(tmp_path / 'logs'),
                   extra=extra)
    process = 'eha_loop' if where == 'in_loop' else 'live'
    assert ('live' in st.commands()) == (where == 'own_process')
    st.start()
    client = None
    try:
        client = FoxgloveClient(f'ws://127.0.0.1:{port}', timeout=90)
        assert client.ws.subprotocol == SUBPROTOCOL
        client.wait_for(lambda: client.server_info is not None, 30, 'serverInfo')
        assert {'services', 'parameters'} <= set(client.server_info['capabilities'])
        topics = ['/eha/state', '/eha/estimate', '/eha/sim/truth']
        client.wait_for(lambda: all(t in client.channels for t in topics + ['/diagnostics']),
                        90, 'advertised channels')
        ch = client.channels['/eha/state']
        assert (ch['encoding'], ch['schemaEncoding'], ch['schemaName']) == \
            ('cdr', 'ros2msg', 'eha_msgs/msg/ActuatorState')
        assert 'float64 position' in ch['schema'] and 'MSG: std_msgs/Header' in ch['schema']
        # the loop must run before the comparison window opens (discovery, start gate)
        assert wait_for(lambda: len(dds['/eha/state']) > 200, 90), 'no states over DDS'
        client.subscribe(topics)
        client.wait_for(lambda: len(client.messages.get('/eha/state', [])) >= 2000 and
                        len(client.messages.get('/eha/estimate', [])) >= 2000, 60,
                        '2000 states and estimates over the WebSocket')
        for topic, cls in (('/eha/state', ActuatorState), ('/eha/estimate', PositionEstimate)):
            ws = {}
            for ts, payload in client.messages[topic]:
                m = deserialize_message(payload, cls)
                stamp = m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
                assert ts == stamp                    # log time = header stamp
                ws[m.seq] = m
            common = set(ws) & set(dds[topic])
            assert len(common) >= 1500, (topic, len(common))
            differ = [s for s in common if ws[s] != dds[topic][s]]   # every field
            assert not differ, (topic, ws[differ[0]], dds[topic][differ[0]])
        # decimation 1:10 on the truth: consecutive seqs 10 apart
        seqs = [deserialize_message(p, PlantTruth).seq
                for _, p in client.messages['/eha/sim/truth']]
        steps = {b - a for a, b in zip(seqs, seqs[1:])}
        assert len(seqs) >= 150 and steps == {10}, (len(seqs), sorted(steps)[:5])
        # a service from the viewer: switch to channel B (1), seen over DDS
        client.wait_for(lambda: '/eha/switch_channel' in client.services, 30, 'services')
        answer = client.call('/eha/switch_channel', {'channel': 1, 'reason': 'live test'})
        assert answer['success'], answer
        assert wait_for(lambda: redundancy and redundancy[-1] == 1, 10), redundancy[-5:]
        with pytest.raises(RuntimeError, match="no field 'bogus'"):
            client.call('/eha/inject_fault', {'bogus': 1})
        # node parameters as node:name
        from eha_ros.core.sim.batch import node_params
        from eha_ros.core.controller.params import SCHEMA
        want = node_params('controller', SCHEMA)['control.rate_limit']
        assert client.get_parameters(['controller:control.rate_limit']) == \
            {'controller:control.rate_limit': want}
    finally:
        if client:
            client.close()
        codes = st.stop()
    assert codes[process][0] == 0, codes[process]


def test_layout_plots_existing_fields():
    """config/foxglove/eha_layout.json: every plotted path is a field of the topic's message
    (topics and types as DESIGN.md's contract; a renamed field fails here)."""
    import json
    import re

    from eha_ros.nodes import msgdefs
    types = {'/eha/state': 'eha_msgs/msg/ActuatorState', '/eha/estimate':
             'eha_msgs/msg/PositionEstimate', '/eha/reference': 'eha_msgs/msg/PositionReference',
             '/eha/command': 'eha_msgs/msg/ActuatorCommand', '/eha/sim/truth':
             'eha_msgs/msg/PlantTruth', '/eha/redundancy': 'eha_msgs/msg/RedundancyStatus'}
    with open('config/foxglove/eha_layout.json') as fh:
        layout = json.load(fh)
    paths = [p['value'] for k, c in layout['configById'].items() if k.startswith('Plot!')
             for p in c['paths']]
    assert len(paths) >= 12
    for path in paths:
        topic, field = re.fullmatch(r'(/[\w/]+)\.(\w+)(?:\[\d\])?', path).groups()
        fields = msgdefs.message_class(types[topic])().get_fields_and_field_types()
        assert field in fields, path
    panels = set(layout['configById'])

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node['first']) + \
            leaves(node['second'])
    assert sorted(leaves(layout['layout'])) == sorted(panels)
