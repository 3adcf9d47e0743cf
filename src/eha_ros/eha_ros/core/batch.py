"""The stack in one process (DESIGN.md "three ways", 3): plant, estimator and position
controller cores stepped tick by tick, with the same parameter files the nodes read.

Tick order as over DDS: state(k) -> estimate(k) -> command(k), applied by the plant at k+1."""
from __future__ import annotations

import os
from dataclasses import dataclass

from .params import default_config_dir, load

# node -> params files in config/ (later files override earlier ones); eha_ros.stack starts the
# node processes with the same files
NODE_FILES = {
    'plant_sim': ['plant.yaml', 'plant_sim.yaml'],
    'estimator': ['plant.yaml', 'estimator.yaml'],
    'controller': ['plant.yaml', 'controller.yaml', 'controller_node.yaml'],
    'switch_manager': ['plant.yaml', 'switch_manager.yaml'],
    'sweep': ['plant.yaml', 'sweep.yaml'],
    'hardware_bridge': ['plant.yaml', 'hardware_bridge.yaml'],
    'recorder': ['recorder.yaml'],
}


def node_params(node: str, schema, config_dir: str | None = None, overrides=None) -> dict:
    config_dir = config_dir or default_config_dir()
    return load(schema, [os.path.join(config_dir, f) for f in NODE_FILES[node]], overrides or {},
                node=node)


@dataclass
class Tick:
    seq: int
    reference: float
    measured: float
    estimate: float
    truth: float
    command: float
    motor_speed_0: float
    motor_speed_1: float
    active_channel: int


class BatchStack:
    """Plant + estimator + controller cores; ``tick(reference, load)`` advances one Ts."""

    def __init__(self, config_dir: str | None = None, seed: int = 1, overrides=None):
        from .controller.params import SCHEMA as CTL
        from .controller.position import PositionController
        from .estimator.estimator import Estimator
        from .estimator.params import SCHEMA as EST
        from .plant import EhaPlant
        from .plant_sim_params import SCHEMA as SIM
        ov = overrides or {}
        self.plant_params = node_params('plant_sim', SIM, config_dir, ov.get('plant_sim'))
        self.plant = EhaPlant(self.plant_params, seed=seed)
        self.plant.reset(position=self.plant_params['sim_node.initial_position'])
        self.estimator = Estimator(node_params('estimator', EST, config_dir, ov.get('estimator')))
        c = node_params('controller', CTL, config_dir, ov.get('controller'))
        self.controller_params = c
        self.controller = PositionController.from_params(c)
        self.Ts = self.plant.Ts
        self.k = 0

    def tick(self, reference: float, load: float = 0.0) -> Tick:
        m = self.plant.measure()
        tr = self.plant.truth()
        est = self.estimator.update(m.position, m.motor_speed, m.pressure_a, m.pressure_b,
                                    m.active_channel)
        self.controller.request(reference)
        out = self.controller.update(est.position)
        rec = Tick(self.k, reference, m.position, est.position, tr.position, out.speed_ref,
                   float(m.motor_speed[0]), float(m.motor_speed[1]), int(m.active_channel))
        self.plant.step(out.speed_ref, load)
        self.k += 1
        return rec
