"""ADS test peer: a TwinCAT-like PLC on loopback (pyads.testserver) whose symbols are backed by
the plant model, so the hardware_bridge closes the loop through real ADS traffic.

    scripts/ads_peer [--lockstep] [--port N] [--no-ros] ...

Serves the symbol map and ADS address of config/hardware_bridge.yaml (bridge.symbol_map,
ads.host, ads.tcp_port) with the plant of config/plant.yaml + plant_sim.yaml (same parameters,
seed and initial position as plant_sim). Real time: the PLC task steps the plant every Ts;
--lockstep: one step per new heartbeat value, i.e. per bridge cycle. A heartbeat that stands
still for --heartbeat-timeout stops the drive (PLC-side watchdog). Unless --no-ros, the peer
also serves /eha/inject_fault (eha_msgs/InjectFault, as plant_sim) and takes
/eha/sim/load_force, from a small ROS node named ads_peer.
"""
from __future__ import annotations

import argparse
import signal
import sys
import threading
import time

from ..core.config.cli import UsageError, guarded
from ..core import topics as T

PROG = 'ads_peer'


def parse(argv):
    ap = argparse.ArgumentParser(prog=PROG, description='ADS test peer: a TwinCAT-like PLC on loopback backed by the plant model.',
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog='\n'.join(__doc__.splitlines()[5:]))
    ap.add_argument('--config', default=None, help='config folder (default: the repository\'s '
                    'config/)')
    ap.add_argument('--symbols', default=None, help='symbol map YAML (default: '
                    'bridge.symbol_map of hardware_bridge.yaml)')
    ap.add_argument('--host', default=None, help='listen address (default: ads.host)')
    ap.add_argument('--port', type=int, default=None, help='ADS/TCP port (default: ads.tcp_port)')
    ap.add_argument('--lockstep', action='store_true',
                    help='step the plant once per new heartbeat value (lock-step with the bridge)')
    ap.add_argument('--seed', type=int, default=None, help='sensor noise seed (default: '
                    'sim_node.seed of plant_sim.yaml)')
    ap.add_argument('--heartbeat-timeout', type=float, default=0.1,
                    help='real time: zero speed when the heartbeat stands still this long [s]')
    ap.add_argument('--no-ros', action='store_true',
                    help='no ROS node (no /eha/inject_fault, no /eha/sim/load_force)')
    ap.add_argument('--duration', type=float, default=0.0, help='stop after this many seconds '
                    '(0 = until Ctrl-C)')
    return ap.parse_args(argv)


def build(args):
    """The peer from the config folder and the arguments (not started)."""
    from ..core.sim.batch import node_params
    from ..core.hardware.bridge_params import SCHEMA as BRIDGE
    from ..core.bridge.peer import AdsPeer
    from ..core.bridge.symbols import load_symbol_map, resolve_path
    from ..core.config.params import default_config_dir
    from ..core.hardware.sim_params import SCHEMA as SIM
    config = args.config or default_config_dir()
    sim = node_params('plant_sim', SIM, config)
    bridge = node_params('hardware_bridge', BRIDGE, config)
    smap = load_symbol_map(resolve_path(args.symbols or bridge['bridge.symbol_map'], config))
    host = args.host or bridge['ads.host']
    port = args.port if args.port is not None else bridge['ads.tcp_port']
    if not 0 < port < 65536:
        raise UsageError(f'--port {port}: expected 1..65535')
    if not args.heartbeat_timeout > 0:
        raise UsageError(f'--heartbeat-timeout {args.heartbeat_timeout}: expected > 0 s')
    try:
        return AdsPeer(smap, sim, host=host, port=port,
                       seed=sim['sim_node.seed'] if args.seed is None else args.seed,
                       lockstep=args.lockstep, heartbeat_timeout=args.heartbeat_timeout,
                       initial_position=sim['sim_node.initial_position'])
    except OSError as err:
        raise UsageError(f'cannot listen on {host}:{port}: {err.strerror}') from None


class PeerNode:
    """A small node: /eha/inject_fault and /eha/sim/load_force into the peer's plant (rclpy
    base: nodes.common.bind)."""

    def __init__(self, peer):
        from eha_msgs.msg import ExternalLoad
        from eha_msgs.srv import InjectFault
        from ..nodes.common import qos_of
        super().__init__('ads_peer')
        self.peer = peer
        self.create_service(InjectFault, T.INJECT_FAULT.name, self.on_fault)
        self.create_subscription(ExternalLoad, T.LOAD_FORCE.name, self.on_load,
                                 qos_of(T.LOAD_FORCE))

    def on_fault(self, req, resp):
        ok, text, tick = self.peer.inject_fault(req.fault, int(req.channel), req.magnitude,
                                                req.duration)
        resp.success, resp.message = bool(ok), f'{text} (tick {tick})' if ok else text
        self.get_logger().info(f'inject_fault {req.fault}: {text}')
        return resp

    def on_load(self, msg):
        import math
        if math.isfinite(msg.force):
            self.peer.set_load(msg.force)


def ros_side(peer):
    """rclpy and the peer's node (PeerNode over DDS)."""
    import rclpy
    from ..nodes.common import bind
    return rclpy, bind(PeerNode)(peer)


def main(argv=None) -> int:
    args = parse(sys.argv[1:] if argv is None else argv)

    def run():
        peer = build(args)
        stop = threading.Event()
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
        rclpy = node = None
        if not args.no_ros:
            import rclpy as _r
            from rclpy.signals import SignalHandlerOptions
            _r.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
            rclpy, node = ros_side(peer)
        peer.start()
        smap = peer.plc.smap
        print(f'{PROG}: serving {len(smap.by_role)} symbols of {smap.path} on '
              f'{peer.host}:{peer.port}, plant stepped '
              f'{"once per heartbeat (lock-step)" if args.lockstep else "every Ts (real time)"}'
              f'{"" if args.no_ros else ", /eha/inject_fault served"}', flush=True)
        end = time.monotonic() + args.duration if args.duration > 0 else None
        try:
            if node is not None:
                from rclpy.executors import SingleThreadedExecutor
                ex = SingleThreadedExecutor()
                ex.add_node(node)
            while not stop.is_set() and (end is None or time.monotonic() < end):
                if node is not None:
                    ex.spin_once(timeout_sec=0.1)
                else:
                    stop.wait(0.1)
        finally:
            peer.stop()
            if node is not None:
                node.destroy_node()
                rclpy.try_shutdown()
        c = peer.plc.counters
        print(f'{PROG}: stopped after {c["plc_cycles"]} PLC cycles, '
              f'{peer.handler.requests} ADS requests, {c["heartbeat_trips"]} heartbeat trips',
              flush=True)
        return 0

    return guarded(PROG, run)


if __name__ == '__main__':
    sys.exit(main())
