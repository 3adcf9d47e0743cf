"""Parameters of the hardware_bridge node: the plant.* set of plant.yaml (shared file; the
bridge uses plant.sim.Ts) plus its own ads.* (link) and bridge.* (safety, lock-step)."""
from __future__ import annotations

from ..params import Param, Schema
from ..plant.parameters import PLANT_SCHEMA
from ..plant_sim_params import lockstep_params

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
          doc='consecutive failed cycles that count as a lost link'),
    Param('ads.reconnect_period', 'float', 's', 0.5, 0.01, 60.0,
          doc='time between reconnection attempts while the link is down'),
    Param('bridge.symbol_map', 'str', '', 'ads_symbols.yaml',
          doc='symbol map YAML; a relative path is taken from the config folder'),
    *lockstep_params('bridge'),
    Param('bridge.max_speed', 'float', 'rad/s', 837.758041, 1.0, 5000.0,
          doc='commands beyond this magnitude are saturated and counted'),
    Param('bridge.max_speed_rate', 'float', 'rad/s^2', 5.0e5, 10.0, 1.0e8,
          doc='rate limit of the speed reference while armed'),
    Param('bridge.watchdog_time', 'float', 's', 0.02, 1e-3, 10.0,
          doc='no command for this long: zero speed written, reported'),
    Param('bridge.stale_limit', 'float', 's', 0.01, 1e-3, 10.0,
          doc='PLC cycle counter standing still (or reads failing) this long: state invalid'),
    Param('bridge.arm_max_command', 'float', 'rad/s', 10.0, 0.0, 5000.0,
          doc='arming is refused while |latest command| exceeds this'),
    Param('bridge.arm_at_start', 'bool', '', False,
          doc='arm by itself once the arming preconditions first hold (explicit operator '
              'choice; default: arm through /eha/bridge/arm)'),
    Param('bridge.startup_discovery', 'float', 's', 2.0, 0.0, 30.0,
          doc='wait this long for other /eha/state publishers before refusing or starting'),
    Param('bridge.diagnostics_period', 'float', 's', 1.0, 0.05, 60.0),
])

SCHEMA = PLANT_SCHEMA + NODE
