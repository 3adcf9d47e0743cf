"""Identification experiments simulated in batch and written as the recorder writes them (the
test side of issue 43 until core/ident/experiments.py defines the signals: then the signals
below move there and this module only simulates and records them).

Each experiment is run on an EhaPlant (drive: speed-reference sweep with a slow position loop
around it) or the stack in one process (BatchStack: estimator and QFT controller from config/),
with default sensor noise, and written to MCAP with the topics and types of the contract:
/eha/state, /eha/command, /eha/reference, /eha/sim/load_force, /eha/experiment.
"""
from __future__ import annotations

import json
import math

import numpy as np

TS = 1e-3
DRIVE_AMPLITUDE = 1000.0 * 2 * math.pi / 60     # [rad/s] 1000 rpm, thesis sec. 3.6.1
DRIVE_FREQS = tuple(range(1, 16))               # [Hz] 1-15 Hz
DRIVE_CENTRING = 4000.0                         # [rad/s per m] slow position loop (~0.2 Hz)


def _sines(freqs, amplitude, periods, least, lead):
    """Stepped sine: each frequency for max(periods / f, least) s after ``lead`` s of zeros."""
    parts = [np.zeros(int(round(lead / TS)))]
    for f in freqs:
        n = int(round(max(periods / f, least) * f) / f / TS)
        t = np.arange(n) * TS
        parts.append(amplitude * np.sin(2 * math.pi * f * t))
    return np.concatenate(parts + [np.zeros(int(round(0.3 / TS)))])


def drive_command():
    """Speed reference sweep 1-15 Hz (thesis Fig. 3.36), before the centring loop [rad/s]."""
    return _sines(DRIVE_FREQS, DRIVE_AMPLITUDE, 2, 0.5, 0.5)


def friction_reference():
    """Position sines of rising frequency, 5 mm (thesis Fig. 3.40) [m]."""
    return _sines((0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0), 5e-3, 2, 0.5, 0.5)


def leakage_load():
    """Held loads of two levels each way (thesis Fig. 3.44) [N]; reference 0."""
    levels = (0.0, 8e3, 16e3, 0.0, -8e3, -16e3, 0.0)
    return np.concatenate([np.full(int(round(3.0 / TS)), f) for f in levels])[
        int(round(2.0 / TS)):]


def validation_signals():
    """5 mm step and back, then a 3 mm 2 Hz sine, under a 6 kN load (thesis Fig. 3.45)."""
    n = int(round(7.0 / TS))
    t = np.arange(n) * TS
    ref = np.where((t >= 0.5) & (t < 2.5), 5e-3, 0.0)
    ref = np.where((t >= 4.0) & (t < 6.0), 3e-3 * np.sin(2 * math.pi * 2.0 * (t - 4.0)), ref)
    return ref, np.full(n, 6e3)


def simulate(experiment: str, overrides: dict, seed: int = 1) -> dict:
    """Per-tick columns of one experiment on the plant with ``overrides`` (plant.* keys)."""
    from eha_ros.core.sim.batch import BatchStack
    from eha_ros.core.sim import closed_loop as CL
    stack = BatchStack(seed=seed, overrides={'plant_sim': dict(overrides)})
    if experiment == 'drive':
        plant = stack.plant
        sweep = drive_command()
        cols = {k: np.empty(len(sweep)) for k in ('x', 'w0', 'w1', 'i0', 'i1', 'pa', 'pb', 'u')}
        for k, w in enumerate(sweep):
            m = plant.measure()
            u = w - DRIVE_CENTRING * m.position
            for key, v in (('x', m.position), ('w0', m.motor_speed[0]),
                           ('w1', m.motor_speed[1]), ('i0', m.motor_current[0]),
                           ('i1', m.motor_current[1]), ('pa', m.pressure_a),
                           ('pb', m.pressure_b), ('u', u)):
                cols[key][k] = v
            plant.step(u, 0.0)
        cols['ch'] = np.zeros(len(sweep))
        return cols
    if experiment == 'friction':
        ref, load = friction_reference(), None
    elif experiment == 'leakage':
        load = leakage_load()
        ref = np.zeros(len(load))
    else:
        ref, load = validation_signals()
    rec = stack.loop.run(ref, load).T
    cols = {'x': rec[CL.R_XM], 'w0': rec[CL.R_WM], 'w1': rec[CL.R_WM + 1], 'i0': rec[CL.R_IM],
            'i1': rec[CL.R_IM + 1], 'pa': rec[CL.R_PM], 'pb': rec[CL.R_PM + 1],
            'u': rec[CL.R_U], 'ch': rec[CL.R_CHANNEL], 'ref': ref}
    if load is not None:
        cols['load'] = load
    return cols


def write(path: str, experiment: str, cols: dict, topics=None, meta: dict | None = None):
    """Columns as an MCAP recording (recorder's topics and types); ``topics`` limits them."""
    from rclpy.serialization import serialize_message
    from eha_msgs.msg import ActuatorCommand, ActuatorState, ExternalLoad, PositionReference
    from std_msgs.msg import String
    from eha_ros.core.io.mcap_sink import McapSink
    from eha_ros.nodes import msgdefs
    sink = McapSink(path)
    wanted = topics or ('/eha/experiment', '/eha/state', '/eha/command', '/eha/reference',
                        '/eha/sim/load_force')

    def channel(topic, type_name):
        cls = msgdefs.message_class(type_name)
        return sink.add_topic(topic, type_name, msgdefs.definition(type_name),
                              msgdefs.header_first(cls))

    ch = {}
    for topic, type_name in (('/eha/experiment', 'std_msgs/msg/String'),
                             ('/eha/state', 'eha_msgs/msg/ActuatorState'),
                             ('/eha/command', 'eha_msgs/msg/ActuatorCommand'),
                             ('/eha/reference', 'eha_msgs/msg/PositionReference'),
                             ('/eha/sim/load_force', 'eha_msgs/msg/ExternalLoad')):
        if topic in wanted and (topic != '/eha/reference' or 'ref' in cols) and \
                (topic != '/eha/sim/load_force' or 'load' in cols):
            ch[topic] = channel(topic, type_name)
    if '/eha/experiment' in ch:
        body = meta if meta is not None else {'experiment': experiment, 'version': 1,
                                              'plant_side': 'sim', 'params': {}}
        sink.put(ch['/eha/experiment'], 0, serialize_message(String(data=json.dumps(body))))

    def stamp(msg, k):
        ns = int(round(k * TS * 1e9)) + 1_000_000_000
        msg.header.stamp.sec, msg.header.stamp.nanosec = ns // 10**9, ns % 10**9
        return ns

    for k in range(len(cols['x'])):
        m = ActuatorState(seq=k, position=float(cols['x'][k]), pressure_a=float(cols['pa'][k]),
                          pressure_b=float(cols['pb'][k]), active_channel=int(cols['ch'][k]))
        m.motor_speed = [float(cols['w0'][k]), float(cols['w1'][k])]
        m.motor_current = [float(cols['i0'][k]), float(cols['i1'][k])]
        ns = stamp(m, k)
        if '/eha/state' in ch:
            sink.put(ch['/eha/state'], ns, serialize_message(m))
        if '/eha/command' in ch:
            c = ActuatorCommand(seq=k, motor_speed_ref=float(cols['u'][k]))
            stamp(c, k)
            sink.put(ch['/eha/command'], ns + 100_000, serialize_message(c))
        if '/eha/reference' in ch:
            r = PositionReference(seq=k, position=float(cols['ref'][k]))
            stamp(r, k)
            sink.put(ch['/eha/reference'], ns, serialize_message(r))
        if '/eha/sim/load_force' in ch:
            f = ExternalLoad(seq=k, force=float(cols['load'][k]))
            stamp(f, k)
            sink.put(ch['/eha/sim/load_force'], ns, serialize_message(f))
    sink.close()
    return path


def record_set(folder, overrides: dict, seed: int = 1) -> list[str]:
    """The four experiments on one plant, written to folder/<experiment>.mcap."""
    import os
    paths = []
    for i, exp in enumerate(('drive', 'friction', 'leakage', 'validation')):
        path = os.path.join(str(folder), f'{exp}.mcap')
        write(path, exp, simulate(exp, overrides, seed + i))
        paths.append(path)
    return paths
