"""hardware_bridge node: the drive and PLC (Beckhoff AX5118 + C6015, TwinCAT) over ADS in place
of plant_sim, with plant_sim's topics (minus truth and sim-only inputs).

Publishes eha/state each cycle, applies eha/command (through core.bridge.Safety: armed only,
saturated, rate limited, watchdog) and eha/channel_select, serves eha/bridge/arm (SetBool)
and eha/bridge/reset (Trigger, clears a latched link fault), reports on /diagnostics;
eha/plant_state (latched) is ACTIVE while armed, so the controller rests while disarmed. All
ADS traffic runs on one I/O thread (one sum read/write request per cycle, core.bridge.link);
ROS callbacks only take a short lock and never publish while holding it. Real time: the
I/O thread cycles at Ts with absolute deadlines. Lock-step (bridge.lockstep): it cycles when
command(k) arrived, publishes /clock and state(k+1); the peer steps on each heartbeat.
Refuses to start while another node publishes eha/state.
"""
from __future__ import annotations

import sys
import threading
import time

from ..core.bridge.link import AdsLink, LinkError, SymbolError
from ..core.bridge.params import SCHEMA
from ..core.bridge.safety import Safety, Staleness
from ..core.bridge.symbols import int_range, load_symbol_map, resolve_path
from ..core.cli import UsageError
from ..core.params import default_config_dir
from ..core.stats import Counters, RingStats
from . import diag
from .common import (PlantState, StartGate, channel_ok, declare_and_validate, latched_qos,
                     node_base, publish_counted, run, stream_qos)


def state_publishers(node, topic: str) -> list[str]:
    """Fully qualified names of the nodes publishing ``topic`` (the bridge's own included)."""
    return [f'{info.node_namespace.rstrip("/")}/{info.node_name}'
            for info in node.get_publishers_info_by_topic(topic)]


def make_node(params: dict):
    Node = node_base()
    from eha_msgs.msg import ActuatorCommand, ActuatorState, ChannelSelect
    from builtin_interfaces.msg import Time
    from rosgraph_msgs.msg import Clock
    from std_srvs.srv import SetBool, Trigger

    class HardwareBridge(Node):
        def __init__(self):
            super().__init__('hardware_bridge')
            self.p = p = declare_and_validate(self, SCHEMA, params)
            self.smap = load_symbol_map(resolve_path(p['bridge.symbol_map'],
                                                     default_config_dir()))
            self.Ts = p['plant.sim.Ts']
            self.lockstep = p['bridge.lockstep']
            self.state_topic = self.resolve_topic_name('eha/state')
            self.refuse_if_other_plant(p['bridge.startup_discovery'])
            self.c = Counters()
            self.safety = Safety(p['bridge.max_speed'], p['bridge.max_speed_rate'],
                                 p['bridge.watchdog_time'], p['bridge.arm_max_command'], self.c)
            self.staleness = Staleness(p['bridge.stale_limit'])
            self.link = AdsLink(self.smap, p['ads.ams_net_id'], p['ads.ams_port'],
                                p['ads.host'], p['ads.tcp_port'], p['ads.timeout'],
                                p['ads.sum_mode'])
            self.lock = threading.Lock()
            self.go = threading.Event()
            self.go_seq = -1                         # lock-step: the tick command(k) came for
            self.k = 0
            self.values = None                       # latest state block {role: SI}
            self.select = None                       # (channel, en0, en1, v0, v1, bypass)
            self.hb = 0
            self.hb_mod = int_range(self.smap['heartbeat'].fmt)[1] + 1
            self.connected = False
            self.fails = 0
            self.next_connect = 0.0
            self.auto_armed = False
            self.conflict = ''
            self.last_error = ''
            self.period = RingStats()
            self.exec_time = RingStats()
            self.state_msg = ActuatorState()
            self.Time, self.Clock = Time, Clock
            # first connection here: a map that does not match the PLC stops the node with one
            # line before anything runs; an unreachable PLC is retried by the I/O thread
            try:
                self.on_connected(self.link.connect())
            except LinkError as err:
                self.last_error = str(err)
            qos = stream_qos()
            self.pub_state = self.create_publisher(ActuatorState, 'eha/state', qos)
            self.pub_diag = diag.publisher(self)
            self.plant_state = PlantState(self)
            self.plant_state.set(False)           # disarmed: commands are not applied
            self.pub_clock = self.create_publisher(Clock, '/clock', 10) if self.lockstep else None
            self.start_gate = StartGate(self, p['bridge.start_after'],
                                        self.state_topic.rsplit('/', 1)[0] + '/',
                                        p['bridge.start_timeout'],
                                        own=(self.pub_state,))
            self.create_subscription(ActuatorCommand, 'eha/command', self.on_command, qos)
            self.create_subscription(ChannelSelect, 'eha/channel_select', self.on_select,
                                     latched_qos())
            self.create_service(SetBool, 'eha/bridge/arm', self.on_arm)
            self.create_service(Trigger, 'eha/bridge/reset', self.on_reset)
            self.create_timer(p['bridge.diagnostics_period'], self.publish_diagnostics)
            self.running = True
            self.done, self.exit_code = False, 0
            self.thread = threading.Thread(target=self.io_loop, name='ads_io', daemon=True)
            self.get_logger().info(
                f'hardware_bridge: {"lock-step" if self.lockstep else "real time"} at '
                f'{1 / self.Ts:.0f} Hz, PLC {self.link.address}, '
                f'{len(self.smap.read)} read + {len(self.smap.write)} write symbols, '
                f'{p["ads.sum_mode"]} sum requests; DISARMED (arm: eha/bridge/arm)'
                + ('' if self.connected else f'; PLC not reachable yet: {self.last_error}'))
            self.thread.start()

        def refuse_if_other_plant(self, wait: float):
            """Another plant (plant_sim or a second bridge) on eha/state: refuse to start."""
            end = time.monotonic() + wait
            while True:
                others = state_publishers(self, self.state_topic)    # ours does not exist yet
                if others:
                    names_by = time.monotonic() + 1.0     # discovery may not know the names yet
                    while any('_UNKNOWN_' in n for n in others) and time.monotonic() < names_by:
                        time.sleep(0.05)
                        others = state_publishers(self, self.state_topic) or others
                    others = [n if '_UNKNOWN_' not in n else 'a node not yet named'
                              for n in others]
                    raise UsageError(f'{self.state_topic} is already published by '
                                     f'{", ".join(others)}: refusing to start a second plant '
                                     f'(stop it first)')
                if time.monotonic() >= end:
                    return
                time.sleep(0.05)

        # ---- ROS callbacks (executor thread, or the I/O thread when composed) ----
        def now(self) -> float:
            """Safety clock: wall time, or plant time k*Ts in lock-step."""
            return self.k * self.Ts if self.lockstep else time.monotonic()

        def on_command(self, msg):
            with self.lock:
                self.safety.set_command(msg.motor_speed_ref, self.now())
                if self.lockstep and msg.seq == self.k:
                    self.go_seq = msg.seq
                    self.go.set()

        def on_select(self, msg):
            if not channel_ok(self, msg, self.c):
                return
            with self.lock:
                self.select = (int(msg.channel), bool(msg.drive_enable[0]),
                               bool(msg.drive_enable[1]), bool(msg.valve_open[0]),
                               bool(msg.valve_open[1]), bool(msg.bypass_open))
            self.c.bump('channel_selects')

        def on_arm(self, req, resp):
            with self.lock:
                if req.data and self.conflict:
                    ok, text = False, f'arming refused: {self.conflict}'
                else:
                    ok, text = self.safety.arm() if req.data else self.safety.disarm('requested')
            resp.success, resp.message = bool(ok), text
            self.log(ok, f'arm={req.data}: {text}')
            self.sync_plant_state()
            return resp

        def sync_plant_state(self):
            """eha/plant_state follows the arming (published outside the lock)."""
            with self.lock:
                armed = self.safety.armed
            self.plant_state.set(armed)

        def on_reset(self, req, resp):
            with self.lock:
                ok, text = self.safety.reset()
            resp.success, resp.message = bool(ok), text
            self.log(ok, f'reset: {text}')
            return resp

        def log(self, ok: bool, text: str):
            """Info when done, warning when refused (rclpy wants one severity per call site)."""
            if ok:
                self.get_logger().info(text)
            else:
                self.get_logger().warning(text)

        # ---- I/O thread ----
        def on_connected(self, command_block: dict):
            """The PLC answered with a matching symbol table: take over its command block."""
            with self.lock:
                self.hb = int(command_block['heartbeat'])
                if self.select is None:
                    b = command_block
                    self.select = (int(b['channel_cmd']), b['drive_enable_0'],
                                   b['drive_enable_1'], b['valve_cmd_0'], b['valve_cmd_1'],
                                   b['bypass_cmd'])
                self.connected = True
                self.fails = 0
                self.safety.set_link(True)

        def io_loop(self):
            try:
                if self.lockstep:
                    self.lockstep_loop()
                else:
                    self.realtime_loop()
            except SymbolError as err:       # the PLC's symbol table changed under us
                self.fatal(str(err))

        def fatal(self, text: str):
            print(f'hardware_bridge: error: {text}', file=sys.stderr, flush=True)
            self.exit_code, self.done, self.running = 2, True, False

        def reconnect(self) -> bool:
            """While the link is down: one attempt per reconnect_period."""
            t = time.monotonic()
            if t < self.next_connect:
                time.sleep(min(0.05, self.next_connect - t))
                return False
            self.next_connect = t + self.p['ads.reconnect_period']
            try:
                block = self.link.connect()
            except LinkError as err:
                self.last_error = str(err)
                self.c.bump('reconnect_failures')
                return False
            self.on_connected(block)
            latched = self.safety.link_fault
            self.get_logger().warning('ADS link to the PLC restored' + (
                '; link fault stays latched until eha/bridge/reset' if latched else ''))
            return True

        def realtime_loop(self):
            """Absolute deadlines at Ts (catch up, or resynchronise when far behind)."""
            while self.running and not self.start_gate.poll():
                time.sleep(0.02)                  # StartGate: a recorder first
            period = self.Ts
            deadline = time.monotonic()
            last = None
            while self.running:
                if not self.connected:
                    if not self.reconnect():
                        self.publish_state(valid=False)   # invalid states at the retry rate
                        continue
                    deadline = time.monotonic()
                deadline += period
                delay = deadline - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                elif -delay > 20 * period:
                    self.c.bump('skipped_deadlines', int(-delay // period))
                    deadline = time.monotonic()
                elif -delay > period:
                    self.c.bump('overruns')
                t = time.monotonic()
                dt = period if last is None else min(t - last, 10 * period)
                if last is not None:
                    self.period.add(t - last)
                last = t
                try:
                    self.cycle(dt)
                except SymbolError:
                    raise
                except Exception as err:      # never die silently in the I/O thread
                    self.c.bump('cycle_errors')
                    self.get_logger().error(f'cycle failed: {err!r}', throttle_duration_sec=1.0)

        def lockstep_loop(self):
            """Cycle on command(k); re-publish state(k) when it does not come."""
            if self.connected:
                self.first_read()
            while self.running:
                if not self.connected:
                    if self.reconnect():
                        self.first_read()
                    continue
                if not self.go.wait(self.p['bridge.lockstep_timeout']):
                    if self.running:
                        self.c.bump('lockstep_waits')
                        self.publish_state(valid=self.staleness.fresh(self.now()))
                    continue
                self.go.clear()
                with self.lock:
                    due = self.go_seq == self.k       # a late duplicate of an older command: no
                while due and self.k == 0 and self.running and not self.start_gate.poll():
                    time.sleep(0.02)              # StartGate: the first cycle waits for it
                if self.running and due:
                    self.cycle(self.Ts)

        def first_read(self):
            """Lock-step start/restart: publish the PLC's state as it is, without a step."""
            try:
                raw = self.link.read_block()
            except LinkError as err:
                self.link_failed(err)
                return
            self.take_values(raw)
            self.publish_state(valid=self.staleness.fresh(self.now()))

        def take_values(self, raw):
            values = self.smap.decode_read(raw)
            with self.lock:
                self.values = values
                fresh = self.staleness.update(int(values['plc_cycle']), self.now())
                ch = int(values['active_channel'])
                fault = bool(values[f'drive_fault_{ch}']) if ch in (0, 1) else True
                self.safety.set_data(fresh, fault)
                if self.p['bridge.arm_at_start'] and not self.auto_armed and \
                        not self.safety.arm_refusal():
                    self.auto_armed = True
                    ok, text = self.safety.arm()
                    self.get_logger().info(f'bridge.arm_at_start: {text}')

        def cycle(self, dt: float):
            """Write command(k) and read the PLC state in one ADS request; publish state(k+1)."""
            t0 = time.perf_counter()
            with self.lock:
                speed = self.safety.speed_output(self.now(), dt)
                self.hb = (self.hb + 1) % self.hb_mod
                ch, en0, en1, v0, v1, bypass = self.select
                block = {'speed_ref': speed, 'channel_cmd': ch, 'drive_enable_0': en0,
                         'drive_enable_1': en1, 'valve_cmd_0': v0, 'valve_cmd_1': v1,
                         'bypass_cmd': bypass, 'heartbeat': self.hb}
            try:
                raw = self.link.cycle(self.smap.encode_write(block))
            except LinkError as err:
                read_ok = False
                self.link_failed(err)
            else:
                read_ok = True
                self.fails = 0
                self.take_values(raw)
            if self.lockstep and not self.connected:
                return                                # no step happened: keep state(k)
            self.k += 1
            with self.lock:
                self.safety.set_data(self.staleness.fresh(self.now()), self.safety.drive_fault)
                # lock-step: a cycle without a read repeats old data, invalid at once
                valid = self.safety.fresh and self.connected and (read_ok or not self.lockstep)
                armed = self.safety.armed
            self.publish_state(valid)
            self.plant_state.set(armed)           # arm_at_start arms in take_values
            self.exec_time.add(time.perf_counter() - t0)

        def link_failed(self, err: LinkError):
            self.fails += 1
            self.c.bump('failed_cycles')
            self.last_error = str(err)
            if self.fails < self.p['ads.link_loss_cycles'] or not self.connected:
                return
            with self.lock:
                was_armed = self.safety.armed
                self.connected = False
                self.safety.set_link(False, str(err))
            self.link.close()
            self.next_connect = time.monotonic() + self.p['ads.reconnect_period']
            self.get_logger().error(
                f'ADS link to the PLC lost after {self.fails} failed cycles ({err})'
                f'{"; disarmed" if was_armed else ""}; fault latched: reset with '
                f'eha/bridge/reset once the link is back')
            self.plant_state.set(False)           # no cycles run until it reconnects

        def stamp(self):
            if self.lockstep:
                ns = int(round(self.k * self.Ts * 1e9))
                st = self.Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
                self.pub_clock.publish(self.Clock(clock=st))
                return st
            ns = time.time_ns()
            return self.Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

        def publish_state(self, valid: bool):
            """Fill the preallocated message in place; never called with the lock held."""
            with self.lock:
                v = self.values
            if v is None:
                return
            s = self.state_msg
            s.header.stamp = self.stamp()
            s.seq = self.k
            s.position = float(v['position'])
            s.pressure_a, s.pressure_b = float(v['pressure_a']), float(v['pressure_b'])
            s.active_channel = int(v['active_channel']) if v['active_channel'] in (0, 1) else 0
            s.bypass_open = bool(v['bypass_open'])
            s.valid = bool(valid)
            speed, current = s.motor_speed, s.motor_current
            valve, enabled, fault = s.valve_open, s.drive_enabled, s.drive_fault
            for i in (0, 1):
                speed[i] = float(v[f'motor_speed_{i}'])
                current[i] = float(v[f'motor_current_{i}'])
                valve[i] = bool(v[f'valve_open_{i}'])
                enabled[i] = bool(v[f'drive_enabled_{i}'])
                fault[i] = bool(v[f'drive_fault_{i}'])
            publish_counted(self, self.pub_state, s, f'state {self.k}')

        # ---- diagnostics (executor thread) ----
        @diag.reader
        def publish_diagnostics(self):
            names = state_publishers(self, self.state_topic)
            others = names if len(names) > 1 else []                 # ours is one of them
            with self.lock:
                if others and not self.conflict:
                    self.conflict = f'{self.state_topic} also published by {", ".join(others)}'
                    self.safety.disarm('second plant on eha/state')
                    self.c.bump('plant_conflicts')
                    self.get_logger().error(f'{self.conflict}: disarmed')
                elif not others:
                    self.conflict = ''
                sf, now = self.safety, self.now()
                values = {'ticks': self.k, 'armed': sf.armed, 'link_up': sf.link_up,
                          'link_fault_latched': sf.link_fault,
                          'link_fault_reason': sf.link_fault_reason, 'data_fresh': sf.fresh,
                          'data_age_s': self.staleness.age(now),
                          'watchdog_tripped': sf.watchdog_tripped, 'speed_ref_out': sf.out,
                          'heartbeat': self.hb, 'last_error': self.last_error,
                          'ads_requests': self.link.requests, 'conflict': self.conflict}
            per, ex = self.period.summary(), self.exec_time.summary()
            values.update({'period_mean_s': per['mean'], 'period_p99_s': per['p99'],
                           'exec_mean_s': ex['mean'], 'exec_p99_s': ex['p99']})
            values.update(self.c)
            if sf.link_fault or not sf.link_up or self.conflict:
                level = diag.ERROR
                msg = self.conflict or ('link fault latched: ' + sf.link_fault_reason
                                        if sf.link_fault else 'no ADS link')
            elif not sf.fresh or sf.watchdog_tripped:
                level, msg = diag.WARN, 'PLC data stale' if not sf.fresh else 'commands stopped'
            else:
                level, msg = diag.OK, 'armed' if sf.armed else 'disarmed'
            diag.publish(self, self.pub_diag, 'link', values, level, msg)
            self.sync_plant_state()

        def close(self):
            self.running = False
            self.go.set()
            if self.thread.is_alive():
                self.thread.join(timeout=2.0)
            if self.connected:          # best effort: leave the drive at zero speed
                try:
                    ch, en0, en1, v0, v1, bypass = self.select
                    self.link.cycle(self.smap.encode_write(
                        {'speed_ref': 0.0, 'channel_cmd': ch, 'drive_enable_0': en0,
                         'drive_enable_1': en1, 'valve_cmd_0': v0, 'valve_cmd_1': v1,
                         'bypass_cmd': bypass, 'heartbeat': self.hb}))
                except LinkError:
                    pass
            self.link.close()

    return HardwareBridge()


def main(argv=None) -> int:
    return run('hardware_bridge', SCHEMA, make_node, argv)


if __name__ == '__main__':
    sys.exit(main())
