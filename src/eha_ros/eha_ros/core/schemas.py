"""Which parameters each node accepts: node name -> Schema (imported lazily)."""
from __future__ import annotations

from importlib import import_module

from .params import ParamError, Schema

# node -> (module, attribute) of its full schema
_REGISTRY = {
    'plant_sim': ('eha_ros.core.plant_sim_params', 'SCHEMA'),
    'estimator': ('eha_ros.core.estimator.params', 'SCHEMA'),
    'controller': ('eha_ros.core.controller.params', 'SCHEMA'),
    'switch_manager': ('eha_ros.core.redundancy.params', 'SCHEMA'),
    'sweep': ('eha_ros.core.sweep.params', 'SCHEMA'),
    'recorder': ('eha_ros.core.recorder_params', 'SCHEMA'),
    'live': ('eha_ros.core.live_params', 'SCHEMA'),
    'hardware_bridge': ('eha_ros.core.bridge.params', 'SCHEMA'),
}


def node_names() -> list[str]:
    return sorted(_REGISTRY)


def schema_for(node: str) -> Schema:
    try:
        module, attr = _REGISTRY[node]
    except KeyError:
        raise ParamError(f'unknown node {node!r}: expected one of {", ".join(node_names())}') \
            from None
    return getattr(import_module(module), attr)
