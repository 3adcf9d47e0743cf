"""``sim`` backend: the nonlinear EHA model (core.plant.EhaPlant, thesis ch. 3) as hardware."""
from __future__ import annotations

import math

from ..plant import EhaPlant
from ..stats import Counters
from .interface import Hardware, Reading


class SimHardware(Hardware):
    """EhaPlant stepped once per write; load force and fault injection are sim-only inputs."""

    kind = 'sim'
    has_truth = True

    def __init__(self, params: dict, counters: Counters, seed: int, initial_position: float,
                 max_load: float):
        self.p = params
        self.c = counters
        self.seed, self.initial_position, self.max_load = seed, initial_position, max_load
        self.plant = None
        self.selection = None        # the latest eha/channel_select, also from before configure
        self.load = 0.0
        self.r = Reading()

    def configure(self) -> str:
        self.plant = EhaPlant(self.p, seed=self.seed)
        self.plant.reset(position=self.initial_position)
        if self.selection is not None:
            self.plant.select(*self.selection)
        return (f'A_p={self.p["plant.cylinder.A_p"]:.4g} m^2, '
                f'D_p={self.p["plant.pump.D_p"]:.4g} m^3/rad, '
                f'substeps={self.p["plant.sim.substeps"]}')

    def set_load(self, value: float) -> None:
        """eha/sim/load_force: non-finite rejected, beyond max_load saturated (counted)."""
        if not math.isfinite(value):
            self.c.bump('rejected_loads')
            return
        if abs(value) > self.max_load:
            self.c.bump('saturated_loads')
            value = math.copysign(self.max_load, value)
        self.load = value

    def write(self, speed: float) -> None:
        self.plant.step(speed, self.load)

    def read(self, now: float) -> Reading:
        self.plant.read_into(self.r)
        return self.r

    def truth(self):
        """Ground truth of the last read (eha/sim/truth): the plant steps only in write(), so
        it is built now, when someone listens, not at every read."""
        return self.plant.truth()

    def select(self, channel, drive_enable, valve_open, bypass_open) -> None:
        self.selection = (channel, tuple(drive_enable), tuple(valve_open), bypass_open)
        if self.plant is not None:
            self.plant.select(*self.selection)

    def inject_fault(self, name: str, channel: int, magnitude: float, duration: float):
        return self.plant.inject_fault(name, channel, magnitude, duration)
