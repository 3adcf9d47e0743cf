"""Parameters of the hardware_bridge node: the plant.* set of plant.yaml (shared file; the
bridge uses plant.sim.Ts) plus its own ads.* (link) and bridge.* (safety, lock-step)."""
from __future__ import annotations

from ..config.params import Param, Schema
from ..plant.parameters import PLANT_SCHEMA
from ..config.registry import LOOP_PREFIX
from .params import loop_params

NODE = Schema('hardware_bridge', [
    Param('ads.ams_net_id', 'str', '', '127.0.0.1.1.1',
          doc='AMS net id of the PLC (TwinCAT: System > Router)'),
    Param('ads.ams_port', 'int', '', 851, 1, 65535, doc='AMS port of the PLC runtime (851 = PLC 1)'),
    Param('ads.host', 'str', '', '127.0.0.1', doc='IP address or host name of the PLC'),
    Param('ads.tcp_port', 'int', '', 48898, 1, 65535, doc='ADS/TCP port (48898 on TwinCAT)'),
    Param('ads.timeout', 'float', 's', 0.1, 0.002, 10.0, doc='ADS request timeout'),
    Param('ads.sum_mode', 'str', '', 'readwrite', choices=('readwrite', 'separate'),
          doc='one sum read/write request per cycle (0xF082) or sum write + sum read'),
    Param('ads.link_loss_cycles', 'int', '', 3, 1, 1000,
          doc='consecutive failed cycles that count as a lost link (latched)'),
    Param('ads.reconnect_period', 'float', 's', 0.5, 0.01, 60.0,
          doc='time between reconnection attempts while the link is down'),
    Param('bridge.symbol_map', 'str', '', 'ads_symbols.yaml',
          doc='symbol map YAML; a relative path is taken from the config folder'),
    Param('bridge.backend', 'str', '', 'ads', choices=('ads', 'mock'),
          doc='ads: the drive over ADS; mock: commands echoed into states (tests, no PLC)'),
    *loop_params(LOOP_PREFIX['hardware_bridge'], command_timeout=0.02, autostart='inactive',
                 startup_discovery=2.0, max_speed_rate=5.0e5, arm_max_command=10.0),
    Param('bridge.stale_limit', 'float', 's', 0.01, 1e-3, 10.0,
          doc='PLC cycle counter standing still (or reads failing) this long: state invalid'),
    Param('bridge.mock_seed', 'int', '', 0, 0, 2**31 - 1,
          doc='mock backend: seed of the position reading\'s noise'),
])

SCHEMA = PLANT_SCHEMA + NODE
