"""``ads`` backend: the drive and PLC (Beckhoff AX5118 + C6015, TwinCAT) over ADS.

configure = symbol map loaded, link up, the PLC's symbol table checked (core.bridge.link).
One sum read/write request per tick: ``write`` sends the command block (speed, redundancy
command, heartbeat) and receives the state block, ``read`` decodes it. A sample whose PLC
cycle counter did not move since the last one (the PLC has not run a cycle in between, e.g.
catch-up ticks after an overrun) is a repeat: published not valid, so the estimator predicts
instead of taking it as a frozen sensor. A sample the PLC took several cycles after the last
one (a late loop cycle) stands for that many ticks (``Reading.ticks``, core.hardware.staleness):
the state's seq moves on by as many, so the estimator predicts over the cycles it did not see
instead of taking the move for a sensor jump. ``link_loss_cycles`` failed requests in a row: link
lost (the gate disarms and latches); ``reconnect`` retries every ``reconnect_period``.
"""
from __future__ import annotations

import time

from ..bridge.link import AdsLink, LinkError
from ..bridge.symbols import int_range, load_symbol_map, resolve_path
from ..config.params import default_config_dir
from ..stats import Counters
from .interface import Hardware, HardwareError, Reading
from .staleness import Staleness


class AdsHardware(Hardware):
    kind = 'ads'

    @property
    def retry_period(self) -> float:
        return self.p['ads.reconnect_period']

    def __init__(self, params: dict, counters: Counters, stale_limit: float):
        p = self.p = params
        self.c = counters
        self.smap = load_symbol_map(resolve_path(p['bridge.symbol_map'], default_config_dir()))
        self.link = AdsLink(self.smap, p['ads.ams_net_id'], p['ads.ams_port'], p['ads.host'],
                            p['ads.tcp_port'], p['ads.timeout'], p['ads.sum_mode'])
        # both counters wrap at their symbol's range (UDINT: 2**32)
        self.staleness = Staleness(stale_limit, int_range(self.smap['plc_cycle'].fmt)[1] + 1)
        self.hb = 0
        self.hb_mod = int_range(self.smap['heartbeat'].fmt)[1] + 1
        self.select_block = None                 # channel_cmd ... bypass_cmd as last commanded
        self.connected = False
        self.fails = 0
        self.next_connect = 0.0
        self.raw = None                          # state block of the last request
        self.read_ok = False
        self.error = ''
        self.lost = ''                           # why the link was declared lost
        self.r = Reading()

    # ---- lifecycle
    def configure(self) -> str:
        try:
            self.on_connected(self.link.connect())    # SymbolError (a ParamError) propagates
        except LinkError as err:
            self.error = str(err)
            raise HardwareError(f'PLC {self.link.address} not reachable: {err}') from None
        return (f'PLC {self.link.address}, {len(self.smap.read)} read + '
                f'{len(self.smap.write)} write symbols, {self.p["ads.sum_mode"]} sum requests')

    def cleanup(self) -> None:
        if self.connected:                       # best effort: leave the drive at zero speed
            try:
                self.link.cycle(self.smap.encode_write(self.block(0.0)))
            except LinkError:
                pass
        self.link.close()
        self.connected = False

    def on_connected(self, command_block: dict):
        """The PLC answered with a matching symbol table: take over its command block."""
        self.hb = int(command_block['heartbeat'])
        if self.select_block is None:
            self.select_block = {k: command_block[k] for k in (
                'channel_cmd', 'drive_enable_0', 'drive_enable_1', 'valve_cmd_0', 'valve_cmd_1',
                'bypass_cmd')}
        self.connected, self.fails, self.lost = True, 0, ''
        self.raw = None
        self.staleness.restart()                 # the PLC's counter may have restarted

    # ---- the loop
    @property
    def link_up(self) -> bool:
        return self.connected

    @property
    def last_error(self) -> str:
        return self.error

    def reconnect(self) -> bool:
        t = time.monotonic()
        if t < self.next_connect:
            time.sleep(min(0.05, self.next_connect - t))
            return False
        self.next_connect = t + self.p['ads.reconnect_period']
        try:
            block = self.link.connect()
        except LinkError as err:
            self.error = str(err)
            self.c.bump('reconnect_failures')
            return False
        self.on_connected(block)
        return True

    def block(self, speed: float) -> dict:
        return dict(self.select_block, speed_ref=speed, heartbeat=self.hb)

    def write(self, speed: float) -> None:
        """Command block out, state block back, in one sum request."""
        self.hb = (self.hb + 1) % self.hb_mod
        try:
            self.raw = self.link.cycle(self.smap.encode_write(self.block(speed)))
        except LinkError as err:
            self.failed(err)
            self.read_ok = False
        else:
            self.fails, self.read_ok = 0, True

    def failed(self, err: LinkError):
        self.fails += 1
        self.c.bump('failed_cycles')
        self.error = str(err)
        if self.fails >= self.p['ads.link_loss_cycles'] and self.connected:
            self.connected = False
            self.lost = f'{self.fails} failed cycles ({err})'
            self.link.close()
            self.next_connect = time.monotonic() + self.p['ads.reconnect_period']

    def read(self, now: float) -> Reading:
        """Decode the state block (before any write: read it alone); ``valid`` only for a new
        sample that arrived with fresh data."""
        if self.raw is None and self.connected:
            try:
                self.raw, self.read_ok = self.link.read_block(), True
            except LinkError as err:
                self.failed(err)
                self.read_ok = False
        r = self.r
        if self.raw is None:
            r.valid = False
            return r
        v = self.smap.decode_read(self.raw)
        new = self.read_ok and self.staleness.update(int(v['plc_cycle']), now)
        if self.read_ok and not new:
            self.c.bump('repeated_samples')
        r.ticks = self.staleness.ticks if self.read_ok else 1
        if r.ticks > 1:
            self.c.bump('skipped_plc_cycles', r.ticks - 1)
        r.position = float(v['position'])
        r.pressure_a, r.pressure_b = float(v['pressure_a']), float(v['pressure_b'])
        ch = int(v['active_channel'])
        r.active_channel = ch if ch in (0, 1) else 0
        r.bypass_open = bool(v['bypass_open'])
        for i in (0, 1):
            r.motor_speed[i] = float(v[f'motor_speed_{i}'])
            r.motor_current[i] = float(v[f'motor_current_{i}'])
            r.valve_open[i] = bool(v[f'valve_open_{i}'])
            r.drive_enabled[i] = bool(v[f'drive_enabled_{i}'])
            r.drive_fault[i] = bool(v[f'drive_fault_{i}'])
        r.active_fault = r.drive_fault[ch] if ch in (0, 1) else True   # no valid couple
        r.valid = new and self.connected and self.staleness.fresh(now)
        self.read_ok = False                     # the next read needs the next request
        return r

    def fresh(self, now: float) -> bool:
        return self.connected and self.staleness.fresh(now)

    def select(self, channel, drive_enable, valve_open, bypass_open) -> None:
        self.select_block = {'channel_cmd': channel, 'drive_enable_0': bool(drive_enable[0]),
                             'drive_enable_1': bool(drive_enable[1]),
                             'valve_cmd_0': bool(valve_open[0]),
                             'valve_cmd_1': bool(valve_open[1]), 'bypass_cmd': bool(bypass_open)}

    def values(self, now: float) -> dict:
        return {'plc': self.link.address, 'heartbeat': self.hb, 'ads_requests': self.link.requests,
                'data_age_s': self.staleness.age(now), 'plc_cycle_jumps': self.staleness.jumps}
