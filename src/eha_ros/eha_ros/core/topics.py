"""The topics of the stack's public contract (docs DESIGN "Public contract"): name, message type
and QoS as plain data, written once. Nodes build their rclpy QoS from it (nodes.common.qos_of);
recordings and readers name channels by ``Topic.path`` (the name resolved in the root
namespace, as an MCAP channel holds it). No rclpy here."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Qos:
    """A QoS profile as plain data (rclpy.qos names, lower case)."""
    depth: int
    reliability: str = 'reliable'          # reliable | best_effort
    durability: str = 'volatile'           # volatile | transient_local
    history: str = 'keep_last'             # keep_last | keep_all


# the 1 kHz streams: reliable, a history deep enough that a recorder or monitor that falls behind
# for a while (lock-step does not wait for it; start-up, a loaded machine) does not lose samples:
# 1 s at 1 kHz (100 lost 6 of 2936 states once on the loaded CI machine, tests/test_recorder.py)
STREAM = Qos(depth=1000)
# low-rate state that late joiners need (channel select, redundancy status, plant state)
LATCHED = Qos(depth=1, durability='transient_local')


@dataclass(frozen=True)
class Topic:
    """One topic: ``name`` relative (remappable, under the node's namespace), ``type`` as
    'package/msg/Class', ``qos`` its publishers' and subscribers' profile."""
    name: str
    type: str
    qos: Qos

    @property
    def path(self) -> str:
        """The name resolved in the root namespace ('/eha/state'), as recordings hold it."""
        return '/' + self.name

    @property
    def package(self) -> str:
        return self.type.split('/')[0]

    @property
    def cls(self) -> str:
        return self.type.split('/')[-1]


STATE = Topic('eha/state', 'eha_msgs/msg/ActuatorState', STREAM)
TRUTH = Topic('eha/sim/truth', 'eha_msgs/msg/PlantTruth', STREAM)
ESTIMATE = Topic('eha/estimate', 'eha_msgs/msg/PositionEstimate', STREAM)
REFERENCE = Topic('eha/reference', 'eha_msgs/msg/PositionReference', STREAM)
COMMAND = Topic('eha/command', 'eha_msgs/msg/ActuatorCommand', STREAM)
REDUNDANCY = Topic('eha/redundancy', 'eha_msgs/msg/RedundancyStatus', LATCHED)
CHANNEL_SELECT = Topic('eha/channel_select', 'eha_msgs/msg/ChannelSelect', LATCHED)
LOAD_FORCE = Topic('eha/sim/load_force', 'eha_msgs/msg/ExternalLoad', STREAM)
# the plant side's lifecycle state (ACTIVE while it applies commands), nodes.common.PlantState
PLANT_STATE = Topic('eha/plant_state', 'lifecycle_msgs/msg/State', LATCHED)
# the identification experiment's description (JSON), nodes.experiment
EXPERIMENT = Topic('eha/experiment', 'std_msgs/msg/String', LATCHED)

TOPICS = (STATE, TRUTH, ESTIMATE, REFERENCE, COMMAND, REDUNDANCY, CHANNEL_SELECT, LOAD_FORCE,
          PLANT_STATE, EXPERIMENT)
BY_NAME = {t.name: t for t in TOPICS}


@dataclass(frozen=True)
class Service:
    """One service: relative name and type ('package/srv/Class')."""
    name: str
    type: str


SWITCH_CHANNEL = Service('eha/switch_channel', 'eha_msgs/srv/SwitchChannel')
INJECT_FAULT = Service('eha/inject_fault', 'eha_msgs/srv/InjectFault')
BRIDGE_ARM = Service('eha/bridge/arm', 'std_srvs/srv/SetBool')
BRIDGE_RESET = Service('eha/bridge/reset', 'std_srvs/srv/Trigger')
SERVICES = (SWITCH_CHANNEL, INJECT_FAULT, BRIDGE_ARM, BRIDGE_RESET)
