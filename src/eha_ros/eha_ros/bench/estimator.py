"""Estimator benchmark: cost per filter update in batch (model KF of eq. 4.35 and PVA, through
Estimator.update and the bare filter, plus filterpy's KalmanFilter for reference) and the
state-to-estimate latency over DDS (plant_sim and estimator as separate processes; the bench
subscribes to /eha/state and /eha/estimate, matches by seq, uses arrival times on its own
monotonic clock). Flat keys, SI units."""
from __future__ import annotations

import os
import signal
import subprocess
import threading
import time

import numpy as np

from ..core.config.params import default_config_dir, load
from ..core.estimator.params import SCHEMA
from ..core import topics as T


def _stats(prefix: str, samples) -> dict:
    a = np.asarray(samples, float)
    if a.size == 0:
        return {f'{prefix}_n': 0}
    return {f'{prefix}_mean_s': float(a.mean()), f'{prefix}_p50_s': float(np.percentile(a, 50)),
            f'{prefix}_p99_s': float(np.percentile(a, 99)), f'{prefix}_max_s': float(a.max()),
            f'{prefix}_n': int(a.size)}


def _params(overrides=None) -> dict:
    cfg = default_config_dir()
    return load(SCHEMA, [os.path.join(cfg, 'plant.yaml'), os.path.join(cfg, 'estimator.yaml')],
                overrides)


def _recorded_measurements(params: dict, n: int):
    """n ticks of plant measurements under a 1 Hz, 5 mm sine (closed on the truth)."""
    from ..core.controller.pid import PID
    from ..core.plant import EhaPlant
    plant = EhaPlant(params, seed=1)
    pid = PID.table_3_8(plant.Ts)
    out, u = [], 0.0
    for k in range(n):
        plant.step(u)
        m = plant.measure()
        out.append((m.position, m.motor_speed.copy(), m.pressure_a, m.pressure_b,
                    m.active_channel))
        u = pid.update(5e-3 * np.sin(2 * np.pi * k * plant.Ts) - plant.position)
    return out


def batch_cost(n: int = 20000) -> dict:
    """Seconds per Estimator.update (validation + predict + Joseph update + fault detector),
    per bare filter step, and per filterpy predict+update of the same model."""
    from ..core.estimator.estimator import Estimator
    res = {}
    base = _params()
    data = _recorded_measurements(base, n)
    for name, over in (('model', {}),
                       ('model_position_only', {'estimator.measurements': 'position'}),
                       ('model_eq4_35', {'estimator.model.structure': 'eq4_35'}),
                       ('pva', {'estimator.filter': 'pva'})):
        p = dict(base)
        p.update(over)
        est = Estimator(p)
        for d in data[:200]:
            est.update(*d)
        dt = []
        for d in data:
            t0 = time.perf_counter_ns()
            est.update(*d)
            dt.append((time.perf_counter_ns() - t0) * 1e-9)
        res.update(_stats(f'update_{name}', dt))
        kf = est.kf
        dt = []
        for d in data:
            t0 = time.perf_counter_ns()
            kf.predict(float(d[1][0]), d[2] - d[3]) if est.is_model else kf.predict()
            kf.update(d[0], d[2], d[3])
            dt.append((time.perf_counter_ns() - t0) * 1e-9)
        res.update(_stats(f'filter_step_{name}', dt))
    # filterpy reference on the same matrices (default model KF, position + p_A, p_B)
    from filterpy.kalman import KalmanFilter
    est = Estimator(base)
    kf = est.kf
    f = KalmanFilter(dim_x=kf.n, dim_z=kf.H.shape[0], dim_u=len(kf.u))
    f.F, f.B, f.Q, f.H, f.R, f.P, f.x = kf.F.copy(), kf.G, kf.Q, kf.H, kf.R, kf.P0.copy(), \
        kf.x.copy()
    dt = []
    for d in data[:5000]:
        z = np.array((d[0], d[2], d[3]))
        u = np.array((float(d[1][0]), 0.0, 1.0))
        t0 = time.perf_counter_ns()
        f.predict(u=u)
        f.update(z)
        dt.append((time.perf_counter_ns() - t0) * 1e-9)
    res.update(_stats('filterpy_step_model', dt))
    res['goal_update_s'] = 100e-6
    return res


def dds_latency(duration: float = 10.0) -> dict:
    """State-to-estimate latency over DDS with plant_sim and estimator as subprocesses."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from eha_msgs.msg import ActuatorState, PositionEstimate
    from ..nodes.common import qos_of
    from ..stack import spawn

    env = dict(os.environ)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))
    os.environ.update({k: env[k] for k in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID')})
    cfg = default_config_dir()
    root = os.path.dirname(cfg)
    vbin = os.path.join(root, '.venv', 'bin')
    plant_cmd = [os.path.join(vbin, 'plant_sim'), '--ros-args', '--params-file',
                 os.path.join(cfg, 'plant.yaml'), '--params-file',
                 os.path.join(cfg, 'plant_sim.yaml')]
    est_cmd = [os.path.join(vbin, 'estimator'), '--ros-args', '--params-file',
               os.path.join(cfg, 'plant.yaml'), '--params-file',
               os.path.join(cfg, 'estimator.yaml')]
    procs = []
    state_t, est_t, stale = {}, {}, [0]
    rclpy.init()
    node = rclpy.create_node(f'bench_estimator_{os.getpid()}')
    try:
        def on_state(msg):
            state_t[msg.seq] = time.monotonic_ns()

        def on_est(msg):
            if msg.stale:
                stale[0] += 1
            else:
                est_t[msg.seq] = time.monotonic_ns()

        node.create_subscription(ActuatorState, T.STATE.path, on_state, qos_of(T.STATE))
        node.create_subscription(PositionEstimate, T.ESTIMATE.path, on_est, qos_of(T.ESTIMATE))
        ex = SingleThreadedExecutor()
        ex.add_node(node)
        stop = threading.Event()
        spin = threading.Thread(target=lambda: [ex.spin_once(timeout_sec=0.05)
                                                for _ in iter(stop.is_set, True)], daemon=True)
        spin.start()
        for cmd in (est_cmd, plant_cmd):
            procs.append(spawn(cmd, env=env, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True))
        end = time.monotonic() + 60.0
        while time.monotonic() < end and len(est_t) < 500:
            time.sleep(0.05)
        state_t.clear()
        est_t.clear()
        stale[0] = 0
        time.sleep(duration)
        stop.set()
        spin.join(timeout=2.0)
        lat = [(est_t[s] - state_t[s]) * 1e-9 for s in est_t if s in state_t]
        out = {}
        a = np.asarray(lat)
        if a.size:
            out.update({'latency_p50_s': float(np.percentile(a, 50)),
                        'latency_p99_s': float(np.percentile(a, 99)),
                        'latency_max_s': float(a.max()), 'latency_mean_s': float(a.mean())})
        n_states = len(state_t)
        out.update({'latency_matched': int(a.size), 'states_received': n_states,
                    'estimates_received': len(est_t), 'stale_estimates': stale[0],
                    'states_without_estimate': int(sum(1 for s in state_t if s not in est_t)),
                    'dds_duration_s': duration})
        return out
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGINT)
        for p in procs:
            try:
                p.communicate(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.communicate()
        node.destroy_node()
        rclpy.try_shutdown()


def run(args=None) -> dict:
    duration = getattr(args, 'duration', None) or 10.0
    res = batch_cost()
    res.update(dds_latency(duration))
    return res
