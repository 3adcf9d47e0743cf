"""Model validation, thesis sec. 3.6.4 (Fig. 3.45): the nominal and the identified plant in the
stack's closed loop against the recorded validation run.

Both models run the same closed loop as the bench did -- core.sim.batch.BatchStack: the plant,
the stack's estimator and controller from config/, tick by tick in the stack's order -- with
the recorded position reference and load, from the recorded initial position, with the
sensors' noise of the same seed for both models (noise-free sensors would look stuck to the
estimator's fault detector); the error is the true simulated position against the recorded
measurement, so the recording's own noise is the floor.
Closed loop, not a replay of the recorded commands into the plant: open loop, any error in the
pump flow integrates into a position drift that the real loop corrects, so the replay would
judge the models by an error the actuator never shows; in the loop, each model meets the
controller as the actuator did, and the nominal and the identified model get the same
reference, load, controller, estimator and start. The errors: position and active motor speed
RMSE over the recorded ticks.

The floor. Even an exact model does not replay the recording tick by tick: the recording's
sensor noise went through the loop (the controller answered it) and the simulation's noise is
another draw; on a plant that sticks and slips the slips move in time by whole milliseconds.
So each model runs with SEEDS noise draws and its figure is the median RMSE, and the floor is
what the identified model scores against itself: the median RMSE of one draw's run against
another draw's simulated recording (its measured position and motor speed) -- the RMSE an
exact model would get, measured without a truth no bench has. A model is better than another
by how far it stays above the floor: ``excess`` = (identified - floor) / (nominal - floor),
judged where the nominal model's error is well above the floor (more than WELL_ABOVE x).
"""
from __future__ import annotations

import numpy as np

INITIAL = 50            # [ticks] averaged for the initial position
SEEDS = (1, 2, 3, 4, 5)  # the sensors' noise draws, the same for both models
WELL_ABOVE = 2.0        # the nominal model's error is judged above this x the floor
SCATTER = 3.0           # a model whose draws' RMSEs differ by more than this factor is not
                        # repeatable under the noise (a loop that sticks and slips, or trips)
QUANTITIES = {'position_rmse_m': ('position', 'measured'),   # simulated, as recorded
              'motor_speed_rmse_rad_s': ('speed', 'speed')}


def closed_loop(rec, overrides: dict, config_dir: str | None, seed: int) -> dict:
    """True and measured position and the measured active motor speed of the loop on the
    plant with ``overrides``, sensor noise drawn from ``seed``."""
    from ..sim.batch import BatchStack
    stack = BatchStack(config_dir=config_dir, seed=seed, overrides={'plant_sim': dict(overrides)})
    stack.plant.reset(position=float(np.mean(rec.position[:INITIAL])))
    out = stack.run(rec.reference, rec.load)
    speed = np.where(out['active_channel'] == 1, out['motor_speed_1'], out['motor_speed_0'])
    return {'position': out['truth'], 'measured': out['measured'], 'speed': speed}


def rmse(a: np.ndarray, b: np.ndarray, use: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a[use] - b[use]) ** 2)))


def validate(rec, identified: dict, config_dir: str | None, log=print) -> dict:
    """Both models against ``rec`` (the validation Recording): median RMSEs over SEEDS, the
    floor, the excess and the signals of the first draw."""
    runs = {'nominal': [closed_loop(rec, {}, config_dir, s) for s in SEEDS],
            'identified': [closed_loop(rec, identified, config_dir, s) for s in SEEDS]}
    use, n = rec.recorded, len(SEEDS)
    recorded = {'position': rec.position, 'speed': rec.speed}
    result = {'seeds': list(SEEDS)}
    for key, (sim, meas) in QUANTITIES.items():
        per = {m: [rmse(r[sim], recorded[sim], use) for r in rs] for m, rs in runs.items()}
        own = runs['identified']
        floor = float(np.median([rmse(own[i][sim], own[(i + 1) % n][meas], use)
                                 for i in range(n)]))
        q = {m: float(np.median(v)) for m, v in per.items()}
        judged = q['nominal'] > WELL_ABOVE * floor
        result[key] = {**q, 'floor': floor, 'runs': per, 'judged': bool(judged),
                       'excess': (q['identified'] - floor) / (q['nominal'] - floor)
                       if judged else None,
                       'repeatable': {m: bool(max(v) <= SCATTER * min(v)) for m, v in per.items()}}
    pos, spd = result['position_rmse_m'], result['motor_speed_rmse_rad_s']
    log(f'identify: validation (median of {n} noise draws): position RMSE '
        f'{pos["nominal"] * 1e6:.0f} um nominal, {pos["identified"] * 1e6:.0f} um identified, '
        f'floor {pos["floor"] * 1e6:.0f} um; motor speed {spd["nominal"]:.1f} / '
        f'{spd["identified"]:.1f} rad/s, floor {spd["floor"]:.1f} rad/s')
    for key in QUANTITIES:
        for m, ok in result[key]['repeatable'].items():
            if not ok:
                v = result[key]['runs'][m]
                log(f'identify: validation: the {m} model\'s loop is not repeatable under the '
                    f'sensor noise ({key}: {min(v):.3g} to {max(v):.3g} over {n} draws): its '
                    f'figure and the floor say little (docs/identification.md, validation)')
    result['signals'] = {'t': rec.t - rec.t[0], 'reference': rec.reference,
                         'position': rec.position, 'speed': rec.speed, 'load': rec.load,
                         **{f'{m}_{k}': rs[0][k] for m, rs in runs.items()
                            for k in ('position', 'speed')}}
    return result
