"""A minimal client of the Foxglove WebSocket protocol (foxglove.websocket.v1,
https://github.com/foxglove/ws-protocol) on the `websockets` package, independent of
foxglove-sdk: serverInfo, advertise, subscribe, binary message data, service calls,
parameters. Used by tests/test_live.py and `scripts/bench live`."""
from __future__ import annotations

import json
import struct
import time

from websockets.sync.client import connect

SUBPROTOCOL = 'foxglove.websocket.v1'
MESSAGE_DATA, TIME, SERVICE_RESPONSE = 0x01, 0x02, 0x03
SERVICE_CALL_REQUEST = 0x02


class FoxgloveClient:
    def __init__(self, url: str, timeout: float = 30.0):
        end = time.monotonic() + timeout
        while True:
            try:
                self.ws = connect(url, subprotocols=[SUBPROTOCOL], open_timeout=5,
                                  max_size=None)
                break
            except OSError:
                if time.monotonic() > end:
                    raise
                time.sleep(0.2)
        self.server_info = None
        self.channels = {}           # topic -> advertised channel dict
        self.services = {}           # name -> advertised service dict
        self.subs = {}               # subscription id -> topic
        self.messages = {}           # topic -> [(timestamp_ns, payload bytes)]
        self.keep = True             # False: count messages only (bench)
        self.counts = {}             # topic -> messages received
        self.responses = {}          # call id -> (encoding, payload)
        self.texts = []              # other JSON ops (parameterValues, status, ...)
        self.times = []
        self.next_call = 1

    def poll(self, seconds: float):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                frame = self.ws.recv(timeout=max(0.01, end - time.monotonic()))
            except TimeoutError:
                return
            self._handle(frame)

    def _handle(self, frame):
        if isinstance(frame, str):
            msg = json.loads(frame)
            op = msg.get('op')
            if op == 'serverInfo':
                self.server_info = msg
            elif op == 'advertise':
                for ch in msg['channels']:
                    self.channels[ch['topic']] = ch
            elif op == 'advertiseServices':
                for sv in msg['services']:
                    self.services[sv['name']] = sv
            else:
                self.texts.append(msg)
            return
        op = frame[0]
        if op == MESSAGE_DATA:
            sub, ts = struct.unpack_from('<IQ', frame, 1)
            topic = self.subs[sub]
            self.counts[topic] = self.counts.get(topic, 0) + 1
            if self.keep:
                self.messages.setdefault(topic, []).append((ts, bytes(frame[13:])))
        elif op == TIME:
            self.times.append(struct.unpack_from('<Q', frame, 1)[0])
        elif op == SERVICE_RESPONSE:
            _, call, n = struct.unpack_from('<III', frame, 1)
            self.responses[call] = (bytes(frame[13:13 + n]).decode(), bytes(frame[13 + n:]))

    def wait_for(self, cond, timeout: float = 30.0, what: str = 'condition'):
        end = time.monotonic() + timeout
        while not cond():
            if time.monotonic() > end:
                raise TimeoutError(f'{what} not met within {timeout:g} s')
            self.poll(0.1)

    def subscribe(self, topics):
        subs = []
        for topic in topics:
            sid = len(self.subs) + 1
            self.subs[sid] = topic
            subs.append({'id': sid, 'channelId': self.channels[topic]['id']})
        self.ws.send(json.dumps({'op': 'subscribe', 'subscriptions': subs}))

    def unsubscribe_all(self):
        self.ws.send(json.dumps({'op': 'unsubscribe', 'subscriptionIds': list(self.subs)}))

    def call(self, service: str, request: dict, timeout: float = 10.0):
        call_id, self.next_call = self.next_call, self.next_call + 1
        enc = b'json'
        frame = struct.pack('<BIII', SERVICE_CALL_REQUEST, self.services[service]['id'],
                            call_id, len(enc)) + enc + json.dumps(request).encode()
        self.ws.send(frame)
        failed = []

        def done():
            failed.extend(t for t in self.texts if t.get('op') == 'serviceCallFailure'
                          and t.get('callId') == call_id)
            return call_id in self.responses or failed
        self.wait_for(done, timeout, f'answer of {service}')
        if failed:
            raise RuntimeError(failed[0].get('message'))
        return json.loads(self.responses[call_id][1])

    def get_parameters(self, names, timeout: float = 10.0):
        return self._parameters({'op': 'getParameters', 'parameterNames': list(names)},
                                timeout)

    def set_parameters(self, values: dict, timeout: float = 10.0):
        return self._parameters({'op': 'setParameters', 'parameters': [
            {'name': k, 'value': v} for k, v in values.items()]}, timeout)

    def _parameters(self, request: dict, timeout: float) -> dict:
        """Send a parameter request with a fresh id; {name: value} of the parameterValues
        answer carrying that id."""
        rid = f'{request["op"]}{time.monotonic_ns()}'
        self.ws.send(json.dumps(dict(request, id=rid)))
        found = []
        self.wait_for(lambda: found.extend(t for t in self.texts if t.get('id') == rid) or found,
                      timeout, f'parameterValues for {request["op"]}')
        return {p['name']: p.get('value') for p in found[0]['parameters']}

    def close(self):
        self.ws.close()
