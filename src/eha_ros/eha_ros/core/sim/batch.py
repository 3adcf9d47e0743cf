"""The stack in one process (DESIGN.md "three ways", 3): plant, estimator and position
controller cores stepped tick by tick, with the same parameter files the nodes read.

Tick order as over DDS: state(k) -> estimate(k) -> command(k), applied by the plant at k+1."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from ..config.params import default_config_dir, load
from ..config.registry import NODE_FILES
from ..loop import safe_state as SAFE


def node_params(node: str, schema, config_dir: str | None = None, overrides=None) -> dict:
    """A node's parameters from its files in config/ (the registry's), as the node loads them
    (``overrides``: -p assignments, ``node:key`` or ``key``)."""
    config_dir = config_dir or default_config_dir()
    return load(schema, [os.path.join(config_dir, f) for f in NODE_FILES[node]], overrides or {},
                node=node)


def nominal_params(config_dir: str | None = None, overrides=None) -> dict:
    """{node: parameter dict} of the loop's nodes (plant_sim and core.config.registry's
    LOOP_NODES) from their files in config/; ``overrides``: {'node:key': value} as -p
    assignments (a scenario's)."""
    from ..config.registry import LOOP_NODES, schema_for
    return {n: node_params(n, schema_for(n), config_dir, overrides)
            for n in ('plant_sim',) + LOOP_NODES}


def build_loop(params: dict, seed: int, faults=None, commands=None, estimator: bool = True,
               manager: bool = True, switch_hold: float | None = None) -> 'BatchLoop':
    """The stack's closed loop in one process, the one place it is assembled: the plant of
    params['plant_sim'] (noise ``seed``, at sim_node.initial_position), the estimator, the
    position controller and the switch manager of params' other node dicts
    (:func:`nominal_params`); without ``estimator`` the controller closes on the measurement,
    without ``manager`` nothing switches. ``switch_hold`` (s) replaces control.switch_hold,
    the controller's integrator hold on a switch. faults, commands: BatchLoop's."""
    from ..controller.position import PositionController
    from ..estimator.estimator import Estimator
    from ..plant import EhaPlant
    from ..redundancy.state_machine import SwitchManager
    plant = EhaPlant(params['plant_sim'], seed=seed)
    plant.reset(position=params['plant_sim']['sim_node.initial_position'])
    c = params['controller']
    hold = c['control.switch_hold'] if switch_hold is None else switch_hold
    return BatchLoop(plant, Estimator(params['estimator']) if estimator else None,
                     PositionController.from_params(c),
                     SwitchManager(params['switch_manager']) if manager else None,
                     int(round(hold / plant.Ts)), faults, commands)


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

    def __init__(self, config_dir: str | None = None, seed: int = 1, overrides=None,
                 faults=None):
        """``overrides``: {node: -p assignments} for plant_sim, estimator, controller;
        ``faults``: BatchLoop's."""
        from ..config.registry import schema_for
        ov = overrides or {}
        params = {n: node_params(n, schema_for(n), config_dir, ov.get(n))
                  for n in ('plant_sim', 'estimator', 'controller')}
        self._loop = build_loop(params, seed, faults=faults, manager=False)
        self.plant_params, self.controller_params = params['plant_sim'], params['controller']
        self.Ts = self.plant.Ts
        self.k = 0

    plant = property(lambda self: self._loop.plant, doc='the loop\'s EhaPlant')
    estimator = property(lambda self: self._loop.est, doc='its Estimator')
    controller = property(lambda self: self._loop.ctl, doc='its PositionController')

    def tick(self, reference: float, load: float = 0.0) -> Tick:
        """One Ts by BatchLoop.tick (the stack's order and its safe state)."""
        from .closed_loop import NREC, R_CHANNEL, R_U, R_WM, R_X0, R_XHAT, R_XM
        row = np.zeros(NREC)
        self.loop.tick(self.k, reference, load, row)
        rec = Tick(self.k, reference, row[R_XM], row[R_XHAT], row[R_X0], row[R_U],
                   row[R_WM], row[R_WM + 1], int(row[R_CHANNEL]))
        self.k += 1
        return rec

    @property
    def loop(self) -> 'BatchLoop':
        return self._loop

    def run(self, references, loads=None, fast: bool = True) -> dict:
        """Ticks self.k .. self.k + n - 1 for arrays of n references (and loads), what n
        :meth:`tick` calls do, in compiled segments (BatchLoop): arrays named as Tick's fields,
        'load' (the loads applied) and 'sensor_offset' (the position sensor's Gauss-Markov
        offset in 'measured')."""
        from .closed_loop import R_CHANNEL, R_GM, R_U, R_WM, R_X0, R_XHAT, R_XM
        refs = np.ascontiguousarray(references, dtype=float)
        loads = np.zeros_like(refs) if loads is None else np.ascontiguousarray(loads, dtype=float)
        rec = self.loop.run(refs, loads, fast=fast, k0=self.k).T
        out = {'seq': np.arange(self.k, self.k + len(refs)), 'reference': refs.copy(),
               'measured': rec[R_XM].copy(), 'estimate': rec[R_XHAT].copy(),
               'truth': rec[R_X0].copy(), 'command': rec[R_U].copy(),
               'motor_speed_0': rec[R_WM].copy(), 'motor_speed_1': rec[R_WM + 1].copy(),
               'active_channel': rec[R_CHANNEL].astype(int), 'load': loads.copy(),
               'sensor_offset': rec[R_GM].copy()}
        self.k += len(refs)
        return out


class BatchLoop:
    """Plant + estimator (or None: the loop closes on the measurement, or with ``on_truth`` on
    the true position) + position controller (the stack's QFT controller, or the Table 3.8 PID
    behind its interface: core.controller.pid.PIDLoop) + switch manager (or None) in one
    process, tick by tick or fast: the one closed-loop harness of the batch runs, campaigns,
    the plant's and the estimator's thesis checks.

    One loop body: a tick is the compiled one of core.sim.closed_loop.segment, for one tick
    (:meth:`tick`) or many (:meth:`run`), and every tick that anything
    event-like touches -- scheduled faults and commands, a monitor verdict the state machine
    acts on, a switch's valve/drive steps, rejected measurements -- is done by the Python
    objects (:meth:`python_tick`, the reference semantics: what the nodes do). Both write
    their row with closed_loop.record and give the same numbers, bit for bit
    (tests/test_batch_fast.py: ``run(fast=False)`` does every tick in Python).
    """

    def __init__(self, plant, estimator, controller, manager=None, hold_ticks: int = 0,
                 faults=None, commands=None, events=None, on_truth: bool = False):
        """faults: {tick: [(name, channel, magnitude, duration), ...]} injected at the tick's
        start; commands: {tick: [(channel, reason), ...]} to the manager after the estimate;
        events: {tick: [callable(plant), ...]} called at the tick's start (after the faults),
        e.g. a channel switch without a manager; on_truth: without an estimator, the
        controller reads the true position instead of the measured one."""
        self.plant, self.est, self.ctl, self.mgr = plant, estimator, controller, manager
        self.hold_ticks = hold_ticks
        self.faults = {int(k): list(v) for k, v in (faults or {}).items()}
        self.commands = {int(k): list(v) for k, v in (commands or {}).items()}
        self.events = {int(k): list(v) for k, v in (events or {}).items()}
        if on_truth and estimator is not None:
            raise ValueError('on_truth: the loop closes on the estimate when there is one')
        self.on_truth = on_truth
        if self.commands and manager is None:
            raise ValueError('commands need a switch manager')
        self.Ts = plant.Ts
        self.u = 0.0                       # latest command (rad/s)
        self.applied = None                # latest channel select applied to the plant
        self.last_status = (manager.active, manager.state) if manager is not None else None
        self.responses = []                # (tick, 'fault' | 'command', (ok, message))
        self.segments = self.fast_ticks = 0
        self.holding = False               # controller in the safe state (core.loop.safe_state)

    def tick(self, k: int, reference: float, load: float, row) -> None:
        """Tick k as the stack does it; writes its record ``row`` (core.sim.closed_loop R_*):
        compiled when nothing event-like is in it, else :meth:`python_tick`."""
        if self._compiled(k):
            one = np.array([float(reference)]), np.array([float(load)])
            if self._segment(k, k + 1, k, *one, row[None, :]) > k:
                return
        self.python_tick(k, reference, load, row)

    def _compiled(self, k: int) -> bool:
        """Tick k may be the compiled one: nothing scheduled at it, nothing Python's pending."""
        return (self.fast_supported() and k not in self.faults and k not in self.commands
                and k not in self.events and self._ready())

    # ------------------------------------------------------------------ reference tick
    def python_tick(self, k: int, reference: float, load: float, row) -> None:
        """Tick k with the Python objects (events included): the reference semantics."""
        from . import closed_loop as CL
        from ..plant.layout import S_GM, S_V
        from ..redundancy.health import ChannelSample
        plant, est, ctl, mgr = self.plant, self.est, self.ctl, self.mgr
        t = k * self.Ts
        for f in self.faults.get(k, ()):
            self.responses.append((k, 'fault', plant.inject_fault(*f)))
        for event in self.events.get(k, ()):
            event(plant)
        m = plant.measure()
        x0, v0, gm0 = plant.position, float(plant.S[S_V]), float(plant.S[S_GM])
        if est is not None:
            r = est.update(m.position, m.motor_speed, m.pressure_a, m.pressure_b,
                           m.active_channel, valid=m.valid, motor_current=m.motor_current)
            x_hat, nis, innov = r.position, r.nis, r.innovation
            code, nd, v_hat, skipped = r.sensor_fault, r.nis_dim, r.velocity, r.update_skipped
            est_ok = r.nis_dim > 0 and not r.sensor_fault
            verdict, w_act, q_leak = r.consistency, r.motor_speed, r.leak_flow
        else:
            x_hat, nis, est_ok, innov, code, nd = m.position, math.nan, False, math.nan, 0, 0
            v_hat, skipped = math.nan, False
            verdict, w_act = 0, float(m.motor_speed[m.active_channel])
            q_leak = math.nan
            if self.on_truth:
                x_hat = x0
        ctl.request(reference)
        if mgr is not None and SAFE.position_fault(verdict):
            mgr.safe_state(SAFE.manager_reason(verdict))
        for ch, why in self.commands.get(k, ()):
            self.responses.append((k, 'command', mgr.request(ch, why)))
        if mgr is not None:
            s = ChannelSample(t, self.u, tuple(m.motor_speed), tuple(m.motor_current),
                              m.pressure_a, m.pressure_b, tuple(m.drive_enabled),
                              tuple(m.drive_fault), m.valid, innov, est_ok)
            mgr.update(s, k)
            if mgr.select != self.applied:     # also after a request() earlier in this tick
                self.applied = sel = mgr.select
                plant.select(sel.channel, sel.drive_enable, sel.valve_open, sel.bypass_open)
            status, last = (mgr.active, mgr.state), self.last_status
            if status != last and (status[0] != last[0] or mgr.state == 'SWITCHING'):
                ctl.hold_integrator(self.hold_ticks)   # as the controller node on /eha/redundancy
            if mgr.pressure_sensor_fault:              # as the controller and estimator nodes
                ctl.stop_leakage_compensation()
                if est is not None:
                    est.stop_pressures()
            self.last_status = status
        if SAFE.controller_holds(verdict, mgr.state if mgr is not None else None):
            u, self.holding = 0.0, True
        else:
            if self.holding:
                self.holding = False
                ctl.start(x_hat)                # bumpless, as the controller node
            u = ctl.update(x_hat, w_act, q_leak).speed_ref
        plant.step(u, load)
        self.u = u
        if mgr is not None:
            from ..redundancy.state_machine import STATE_CODES
            active, state = mgr.active, STATE_CODES[mgr.name]
        else:
            active = state = m.active_channel
        CL.record(row, plant.arrays, float(x0), v0, gm0, float(m.position),
                  np.asarray(m.motor_speed, float), np.asarray(m.motor_current, float),
                  float(m.pressure_a), float(m.pressure_b), int(m.active_channel), float(x_hat),
                  float(v_hat), float(u), float(nis), float(innov), int(code), int(nd),
                  int(verdict), float(skipped), int(active), int(state))

    # ------------------------------------------------------------------ fast run
    def run(self, references, loads=None, fast: bool = True, k0: int = 0):
        """Ticks k0 .. k0+n-1 with references[i], loads[i] (arrays of n); returns the
        (n, NREC) record (core.sim.closed_loop R_* columns, row i = tick k0 + i)."""
        from .closed_loop import NREC
        refs = np.ascontiguousarray(references, dtype=float)
        n = len(refs)
        loads = np.zeros(n) if loads is None else np.ascontiguousarray(loads, dtype=float)
        if loads.shape != refs.shape:
            raise ValueError(f'{len(loads)} loads for {n} references: expected as many')
        rec = np.zeros((n, NREC))
        k, end = k0, k0 + n
        fast = fast and self.fast_supported()
        scheduled = sorted(set(self.faults) | set(self.commands) | set(self.events))
        retry, wait = k, 1           # back off while segments stop at once (e.g. a stuck sensor)
        while k < end:
            stop = min([s for s in scheduled if s >= k] + [end])
            if fast and retry <= k < stop and self._ready():
                start = k
                k = self._segment(k, stop, k0, refs, loads, rec)
                if k >= end:
                    break
                wait = 1 if k > start else min(2 * wait, 64)
                retry = k + 1 if k > start else k + wait
            self.python_tick(k, refs[k - k0], loads[k - k0], rec[k - k0])
            k += 1
        return rec

    def fast_supported(self) -> bool:
        """The compiled segment covers this loop: the stack's controller, closing on the
        estimate or the measurement, an estimator configuration its kernel covers."""
        from ..controller.position import PositionController
        from ..estimator import stepper as ES
        return isinstance(self.ctl, PositionController) and not self.on_truth and \
            (self.est is None or ES.supported(self.est))

    def _ready(self) -> bool:
        """Cheap Python-side check before packing: nothing that surely needs a Python tick."""
        est = self.est
        return (est is None or (est.started and est._saved is None and
                                not (est.isolate and est.detector.code))) and \
            self.ctl.started and not self.holding

    def _segment(self, k: int, stop: int, off: int, refs, loads, rec) -> int:
        """Compiled ticks k .. stop-1 until one needs Python; returns that tick (or stop)."""
        from . import closed_loop as CL
        from ..controller import stepper as CS
        from ..redundancy import stepper as RS
        from ..kernel_records import placeholder
        plant, est, ctl, mgr = self.plant, self.est, self.ctl, self.mgr
        est_kernel = est.kernel if est is not None else _dummy_estimator()
        ctl_kernel = CS.pack(ctl)
        mgr_arrays = RS.pack(mgr) if mgr is not None else placeholder(RS.Arrays)
        u = self.u
        while True:
            k0 = k
            k, why, u = CL.segment(k, stop, off, self.Ts, refs, loads, plant.arrays,
                                   plant._nsub, est_kernel, est is not None,
                                   ctl_kernel, mgr_arrays, mgr is not None,
                                   u, rec)
            self.segments += 1
            self.fast_ticks += k - k0
            if why != CL.NOISE:
                break
            plant._noise.refill()             # the block is used up: the next one
        self.u = float(u)
        CS.unpack(ctl, ctl.s)
        if mgr is not None:
            RS.unpack(mgr, mgr_arrays)
        return k


def _dummy_estimator():
    """Arrays of the estimator stepper's types when the loop has no estimator."""
    from ..estimator import stepper as ES
    from ..kernel_records import placeholder
    return (*ES.new_records(), placeholder(ES.Arrays))
