"""ADS test peer: a TwinCAT-like PLC on loopback whose process image is backed by EhaPlant.

:class:`PlantPlc` is the PLC program (one call per 1 ms task cycle: command symbols -> plant
inputs, one plant step, plant measurement -> state symbols; a heartbeat watchdog stops the
drive when the bridge's counter stands still). :class:`PeerHandler` answers ADS requests on
those symbols through ``pyads.testserver``, adding what its stock AdvancedHandler lacks:
ADS error codes instead of a dead connection for unknown symbols, sum read/write (0xF082),
and a lock shared with the cycle. :class:`PeerServer` frames TCP properly (the stock server
assumes one recv() = one packet). Lock-step: the PLC steps once each time the heartbeat
changes (one step per bridge cycle); real time: a thread steps it every Ts.
"""
from __future__ import annotations

import math
import select
import socket
import struct
import threading
import time

from pyads import constants
from pyads.testserver import AdsTestServer, AdvancedHandler, PLCVariable
from pyads.testserver.handler import AmsResponseData
from pyads.testserver.testserver import AdsClientConnection

from ..plant import EhaPlant
from .link import (ADSERR_SYMBOLNOTFOUND, ADSIGRP_SUMUP_READ, ADSIGRP_SUMUP_READWRITE,
                   ADSIGRP_SUMUP_WRITE, ADSIGRP_SYM_INFOBYNAMEEX)
from .symbols import SymbolMap

ADSERR_INVALIDGRP = 0x702
ADSERR_INVALIDSIZE = 0x705
ADSERR_SRVNOTSUPP = 0x701
ADSIGRP_SYM_HNDBYNAME = 0xF003
ADSIGRP_SYM_VALBYHND = 0xF005
ADSIGRP_SYM_RELEASEHND = 0xF006
PEER_INDEX_GROUP = 0x4040           # %M area of a TwinCAT PLC, like a real symbol table


class PlantPlc:
    """The PLC program: process image of the symbol map around an EhaPlant."""

    def __init__(self, smap: SymbolMap, plant_params: dict, seed: int = 1,
                 lockstep: bool = False, heartbeat_timeout: float = 0.1,
                 initial_position: float = 0.0):
        self.smap = smap
        EhaPlant(plant_params, seed=seed).step(0.0)      # compile the kernels before serving
        self.plant = EhaPlant(plant_params, seed=seed)
        self.plant.reset(position=initial_position)
        self.Ts = self.plant.Ts
        self.lockstep = lockstep
        self.heartbeat_timeout = heartbeat_timeout
        self.vars: dict[str, PLCVariable] = {}
        for i, sym in enumerate(smap.read + smap.write):
            self.vars[sym.role] = PLCVariable(sym.name, sym.to_plc(0), sym.ads_type,
                                              sym.plc_type, index_group=PEER_INDEX_GROUP,
                                              index_offset=0x1000 + 16 * i)
        self.cycles = 0
        self.load_force = 0.0
        self.last_hb = 0                 # the heartbeat symbol starts at 0
        self.last_hb_time = None
        self.hb_tripped = False
        self.counters = {'plc_cycles': 0, 'heartbeat_trips': 0, 'lockstep_steps': 0}
        self.speed_log = []            # (cycle, wall time, speed_ref rad/s) while recording
        self.recording = False
        m = self.plant.measure()
        self.set('channel_cmd', 0)
        self.set('drive_enable_0', bool(m.drive_enabled[0]))
        self.set('drive_enable_1', bool(m.drive_enabled[1]))
        self.set('valve_cmd_0', True)
        self.set('valve_cmd_1', False)
        self._outputs()

    # -------------------------------------------------- process image
    def get(self, role: str):
        sym = self.smap[role]
        return sym.to_si(struct.unpack('<' + sym.fmt, self.vars[role].value)[0])

    def set(self, role: str, value):
        sym = self.smap[role]
        self.vars[role].value = struct.pack('<' + sym.fmt, sym.to_plc(value))

    def _outputs(self):
        m, tr = self.plant.measure(), self.plant.truth()
        s = self.set
        s('plc_cycle', self.cycles % (2 ** (8 * self.smap['plc_cycle'].size)))
        s('position', float(m.position))
        for i in (0, 1):
            s(f'motor_speed_{i}', float(m.motor_speed[i]))
            s(f'motor_current_{i}', float(m.motor_current[i]))
            s(f'valve_open_{i}', bool(m.valve_open[i] > 0.5))
            s(f'drive_enabled_{i}', bool(m.drive_enabled[i]))
            s(f'drive_fault_{i}', bool(m.drive_fault[i]))
        s('pressure_a', float(m.pressure_a))
        s('pressure_b', float(m.pressure_b))
        s('active_channel', int(m.active_channel))
        s('bypass_open', bool(tr.bypass_fraction > 0.5))

    # -------------------------------------------------- PLC task
    def cycle(self, now: float | None = None):
        """One PLC task cycle: apply the command symbols, step the plant, update the state."""
        now = time.monotonic() if now is None else now
        speed = float(self.get('speed_ref'))
        hb = self.get('heartbeat')
        if hb != self.last_hb:
            self.last_hb, self.last_hb_time = hb, now
            self.hb_tripped = False
        alive = self.lockstep or (self.last_hb_time is not None and
                                  now - self.last_hb_time <= self.heartbeat_timeout)
        if not alive:                   # PLC-side stop: no bridge yet, or it went silent
            if self.last_hb_time is not None and not self.hb_tripped:
                self.hb_tripped = True
                self.counters['heartbeat_trips'] += 1
            speed = 0.0
        if not math.isfinite(speed):
            speed = 0.0
        channel = int(self.get('channel_cmd'))
        self.plant.select(channel if channel in (0, 1) else self.plant.active_channel,
                          (self.get('drive_enable_0'), self.get('drive_enable_1')),
                          (self.get('valve_cmd_0'), self.get('valve_cmd_1')),
                          self.get('bypass_cmd'))
        if self.recording:
            self.speed_log.append((self.cycles, now, speed))
        self.plant.step(speed, self.load_force)
        self.cycles += 1
        self.counters['plc_cycles'] = self.cycles
        self._outputs()

    def after_write(self):
        """Lock-step: a new heartbeat value written = the bridge finished one cycle: step."""
        if self.lockstep and self.get('heartbeat') != self.last_hb:
            self.counters['lockstep_steps'] += 1
            self.cycle()

    def inject_fault(self, name, channel, magnitude, duration):
        return self.plant.inject_fault(name, channel, magnitude, duration)


class PeerHandler(AdvancedHandler):
    """ADS request handler on the PLC's symbols (thread-safe, with ADS error codes)."""

    def __init__(self, plc: PlantPlc):
        super().__init__()
        self.plc = plc
        self.lock = threading.Lock()
        self.online = True                # False: requests go unanswered (cable pulled)
        self.by_name = {v.name.lower(): v for v in plc.vars.values()}
        self.by_handle = {v.handle: v for v in plc.vars.values()}
        for v in plc.vars.values():
            self.add_variable(v)
        self.requests = 0

    def handle_request(self, request):
        with self.lock:
            if not self.online:
                return None
            self.requests += 1
            cmd = struct.unpack('<H', request.ams_header.command_id)[0]
            state = struct.pack('<H', struct.unpack('<H', request.ams_header.state_flags)[0] | 1)
            data = request.ams_header.data
            try:
                if cmd == constants.ADSCOMMAND_READWRITE:
                    body = self._read_write(data)
                elif cmd == constants.ADSCOMMAND_READ:
                    g, o, n = struct.unpack_from('<III', data)
                    value = self._var(g, o).value[:n]
                    body = struct.pack('<II', 0, len(value)) + value
                elif cmd == constants.ADSCOMMAND_WRITE:
                    g, o, n = struct.unpack_from('<III', data)
                    if g != ADSIGRP_SYM_RELEASEHND:
                        self._write(self._var(g, o), data[12:12 + n])
                        self.plc.after_write()
                    body = struct.pack('<I', 0)
                else:
                    return super().handle_request(request)
            except _AdsFault as err:
                body = struct.pack('<I', err.code) + (
                    b'' if cmd == constants.ADSCOMMAND_WRITE else struct.pack('<I', 0))
            return AmsResponseData(state, request.ams_header.error_code, body)

    def _var(self, group, offset) -> PLCVariable:
        if group == ADSIGRP_SYM_VALBYHND:
            var = self.by_handle.get(offset)
        else:
            var = self._data.get((group, offset))
        if var is None:
            raise _AdsFault(ADSERR_INVALIDGRP if group != PEER_INDEX_GROUP else 0x703)
        return var

    def _write(self, var: PLCVariable, value: bytes):
        if len(value) != var.size:
            raise _AdsFault(ADSERR_INVALIDSIZE)
        var.value = bytes(value)

    def _read_write(self, data: bytes) -> bytes:
        g, o, rlen, wlen = struct.unpack_from('<IIII', data)
        wdata = data[16:16 + wlen]
        if g in (ADSIGRP_SYM_INFOBYNAMEEX, ADSIGRP_SYM_HNDBYNAME):
            name = wdata.split(b'\x00')[0].decode('utf-8', 'replace').strip().lower()
            var = self.by_name.get(name)
            if var is None:
                raise _AdsFault(ADSERR_SYMBOLNOTFOUND)
            out = var.get_packed_info() if g == ADSIGRP_SYM_INFOBYNAMEEX else \
                struct.pack('<I', var.handle)
        elif g == ADSIGRP_SUMUP_READ:
            items = [struct.unpack_from('<III', wdata, 12 * i) for i in range(o)]
            codes, values = [], []
            for ig, io, n in items:
                try:
                    values.append(self._var(ig, io).value[:n])
                    codes.append(0)
                except _AdsFault as err:
                    codes.append(err.code)
                    values.append(bytes(n))
            out = struct.pack(f'<{o}I', *codes) + b''.join(values)
        elif g == ADSIGRP_SUMUP_WRITE:
            items = [struct.unpack_from('<III', wdata, 12 * i) for i in range(o)]
            pos, codes = 12 * o, []
            for ig, io, n in items:
                codes.append(self._try_write(ig, io, wdata[pos:pos + n]))
                pos += n
            self.plc.after_write()
            out = struct.pack(f'<{o}I', *codes)
        elif g == ADSIGRP_SUMUP_READWRITE:
            # all writes first, then the PLC hook (lock-step step), then all reads
            items = [struct.unpack_from('<IIII', wdata, 16 * i) for i in range(o)]
            pos, codes = 16 * o, [0] * o
            for i, (ig, io, rn, wn) in enumerate(items):
                if wn:
                    codes[i] = self._try_write(ig, io, wdata[pos:pos + wn])
                    pos += wn
            self.plc.after_write()
            values = []
            for i, (ig, io, rn, wn) in enumerate(items):
                value = b''
                if rn and not codes[i]:
                    try:
                        value = self._var(ig, io).value[:rn]
                    except _AdsFault as err:
                        codes[i] = err.code
                values.append(value)
            out = b''.join(struct.pack('<II', c, len(v)) for c, v in zip(codes, values)) + \
                b''.join(values)
        else:
            raise _AdsFault(ADSERR_SRVNOTSUPP)
        if len(out) > rlen:
            raise _AdsFault(ADSERR_INVALIDSIZE)
        return struct.pack('<II', 0, len(out)) + out

    def _try_write(self, ig, io, value) -> int:
        try:
            self._write(self._var(ig, io), value)
            return 0
        except _AdsFault as err:
            return err.code


class _AdsFault(Exception):
    def __init__(self, code: int):
        super().__init__(code)
        self.code = code


class FramedConnection(AdsClientConnection):
    """Client connection that reads whole AMS/TCP packets (6-byte header + length)."""

    def run(self):
        buf = b''
        while self._run:
            try:
                ready, _, _ = select.select([self.client], [], [], 0.1)
            except (OSError, ValueError):
                break
            if not ready:
                continue
            try:
                chunk = self.client.recv(65536)
            except OSError:
                chunk = b''
            if not chunk:
                break
            buf += chunk
            while len(buf) >= 6:
                length = struct.unpack_from('<I', buf, 2)[0]
                if len(buf) < 6 + length:
                    break
                packet, buf = buf[:6 + length], buf[6 + length:]
                if len(packet) < 38:
                    continue
                request = self.construct_request(packet)
                response = self.handler.handle_request(request)
                if isinstance(response, AmsResponseData):
                    try:
                        self.client.sendall(self.construct_response(response, request))
                    except OSError:
                        self._run = False
                        break
        self._run = False
        try:
            self.client.close()
        except OSError:
            pass

    def stop(self):
        self._run = False
        if threading.current_thread() is not self:
            self.join(timeout=1.0)


class PeerServer(AdsTestServer):
    """AdsTestServer with framed client connections and no request history (it grows)."""

    def run(self):
        self._run = True
        self.server.listen(5)
        while self._run:
            try:
                ready, _, _ = select.select([self.server], [], [], 0.1)
            except (OSError, ValueError):
                break
            if not ready:
                continue
            try:
                client, address = self.server.accept()
            except OSError:
                continue
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn = FramedConnection(handler=self.handler, client=client, address=address,
                                    server=self)
            conn.daemon = True
            conn.start()
            self.clients = [c for c in self.clients if c.is_alive()] + [conn]

    def drop_clients(self):
        """Close every client connection (a PLC restart as the bridge sees it)."""
        for c in list(self.clients):
            try:
                c.client.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            c.stop()
        self.clients = []


class AdsPeer:
    """The whole peer: PLC program + ADS server + (real time) the 1 kHz task thread."""

    def __init__(self, smap: SymbolMap, plant_params: dict, host: str = '127.0.0.1',
                 port: int = 48898, seed: int = 1, lockstep: bool = False,
                 heartbeat_timeout: float = 0.1, initial_position: float = 0.0):
        self.plc = PlantPlc(smap, plant_params, seed, lockstep, heartbeat_timeout,
                            initial_position)
        self.handler = PeerHandler(self.plc)
        self.host, self.port = host, port
        self.server = PeerServer(handler=self.handler, ip_address=host, port=port,
                                 logging=False)
        self.lockstep = lockstep
        self.running = False
        self.overruns = 0
        self.thread = None

    @property
    def lock(self):
        return self.handler.lock

    def start(self):
        self.running = True
        # listen before the server thread runs: a client connecting at once queues in the
        # backlog instead of being refused (seen on a loaded machine: ADS error 6)
        self.server.server.listen(5)
        self.server.start()
        if not self.lockstep:
            self.thread = threading.Thread(target=self._task, name='plc_task', daemon=True)
            self.thread.start()
        return self

    def _task(self):
        """PLC task at Ts with absolute deadlines (resynchronised when far behind)."""
        period = self.plc.Ts
        deadline = time.monotonic()
        while self.running:
            deadline += period
            delay = deadline - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif -delay > 20 * period:
                self.overruns += 1
                deadline = time.monotonic()
            with self.lock:
                self.plc.cycle()

    def set_online(self, online: bool):
        """False: the PLC stops answering (a pulled cable); True: it answers again."""
        with self.lock:
            self.handler.online = online

    def inject_fault(self, name, channel, magnitude, duration):
        with self.lock:
            ok, text = self.plc.inject_fault(name, channel, magnitude, duration)
            return ok, text, self.plc.cycles

    def set_load(self, force: float):
        with self.lock:
            self.plc.load_force = float(force)

    def stop(self):
        self.running = False
        if self.thread is not None:
            self.thread.join(timeout=2.0)
        self.server.drop_clients()
        self.server.stop()
