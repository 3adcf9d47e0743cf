"""``mock`` backend: commands echoed into states, no physics (ros2_control's mock components).

The active couple's motor speed is the commanded speed; the piston follows the ideal pump
kinematics x' = D_p omega / A_p (thesis eq. 3.1 and 3.8 without leakage, compressibility or
load) and stops at the end stops (+-stroke/2). Pressures stay at the accumulator's initial
pressure. The position reading carries the sensor's white noise and resolution
(plant.sensors.*, seeded) so that a model-based estimator does not see a frozen sensor.
Fault ``no_feedback`` (eha/inject_fault): the PLC-like cycle counter stops and the readings
freeze, so the data goes stale (the gate stops the drive, states are invalid).
"""
from __future__ import annotations

import numpy as np

from ..stats import Counters
from .interface import Hardware, Reading
from .staleness import Staleness

FAULTS = ('no_feedback', 'clear')


class MockHardware(Hardware):
    kind = 'mock'

    def __init__(self, params: dict, counters: Counters, stale_limit: float, seed: int = 0):
        p = params
        self.c = counters
        self.Ts = p['plant.sim.Ts']
        self.ratio = p['plant.pump.D_p'] / p['plant.cylinder.A_p']      # m/rad
        self.x_max = 0.5 * p['plant.cylinder.stroke']
        self.sigma = p['plant.sensors.position_sigma'] if p['plant.sensors.noise'] else 0.0
        self.resolution = p['plant.sensors.position_resolution']
        self.pressure = p['plant.accumulator.p_init']
        self.rng = np.random.default_rng(seed)
        self.staleness = Staleness(stale_limit)
        self.x = 0.0
        self.speed = 0.0
        self.channel, self.enable, self.valves, self.bypass = 0, [True, False], [True, False], False
        self.cycle = 0
        self.frozen_ticks = 0                    # no_feedback: ticks left (-1: until cleared)
        self.r = Reading()

    def configure(self) -> str:
        return f'mock: x\' = D_p omega / A_p = {self.ratio:.4g} m/rad x omega, no physics'

    def write(self, speed: float) -> None:
        driving = self.enable[self.channel] and self.valves[self.channel] and not self.bypass
        self.speed = speed if driving else 0.0
        self.x = float(np.clip(self.x + self.ratio * self.speed * self.Ts, -self.x_max, self.x_max))
        if self.frozen_ticks:
            self.frozen_ticks -= self.frozen_ticks > 0
            return
        self.cycle += 1

    def read(self, now: float) -> Reading:
        r = self.r
        new = self.staleness.update(self.cycle, now)
        if new:
            z = self.x + (self.sigma * self.rng.standard_normal() if self.sigma else 0.0)
            r.position = round(z / self.resolution) * self.resolution if self.resolution else z
            r.pressure_a = r.pressure_b = self.pressure
            r.active_channel, r.bypass_open = self.channel, self.bypass
            for i in (0, 1):
                r.motor_speed[i] = self.speed if i == self.channel else 0.0
                r.motor_current[i] = 0.0
                r.valve_open[i] = self.valves[i]
                r.drive_enabled[i] = self.enable[i]
                r.drive_fault[i] = False
            r.active_fault = False
        r.valid = new and self.staleness.fresh(now)
        return r

    def fresh(self, now: float) -> bool:
        return self.staleness.fresh(now)

    def select(self, channel, drive_enable, valve_open, bypass_open) -> None:
        self.channel = channel
        self.enable, self.valves = list(drive_enable), list(valve_open)
        self.bypass = bool(bypass_open)

    def inject_fault(self, name: str, channel: int, magnitude: float, duration: float):
        if name == 'clear':
            self.frozen_ticks = 0
            return True, 'cleared'
        if name != 'no_feedback':
            return False, f'mock backend: unknown fault {name!r} (expected one of {FAULTS})'
        self.frozen_ticks = -1 if duration <= 0 else max(1, int(round(duration / self.Ts)))
        return True, ('no_feedback until cleared' if duration <= 0 else
                      f'no_feedback for {duration:g} s')

    def values(self, now: float) -> dict:
        return {'mock_cycle': self.cycle, 'no_feedback': bool(self.frozen_ticks),
                'data_age_s': self.staleness.age(now)}
