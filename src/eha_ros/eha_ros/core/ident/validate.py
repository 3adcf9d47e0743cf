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
"""
from __future__ import annotations

import numpy as np

INITIAL = 50            # [ticks] averaged for the initial position
SEED = 1                # the sensors' noise draws, the same for both models


def closed_loop(rec, overrides: dict, config_dir: str | None) -> dict:
    """Position and active motor speed of the loop on the plant with ``overrides``."""
    from ..sim.batch import BatchStack
    stack = BatchStack(config_dir=config_dir, seed=SEED, overrides={'plant_sim': dict(overrides)})
    stack.plant.reset(position=float(np.mean(rec.position[:INITIAL])))
    out = stack.run(rec.reference, rec.load)
    speed = np.where(out['active_channel'] == 1, out['motor_speed_1'], out['motor_speed_0'])
    return {'position': out['truth'], 'speed': speed}


def rmse(a: np.ndarray, b: np.ndarray, use: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a[use] - b[use]) ** 2)))


def validate(rec, identified: dict, config_dir: str | None, log=print) -> dict:
    """Both models against ``rec`` (the validation Recording): RMSEs and the signals."""
    runs = {'nominal': closed_loop(rec, {}, config_dir),
            'identified': closed_loop(rec, identified, config_dir)}
    use = rec.recorded
    result = {'position_rmse_m': {m: rmse(r['position'], rec.position, use)
                                  for m, r in runs.items()},
              'motor_speed_rmse_rad_s': {m: rmse(r['speed'], rec.speed, use)
                                         for m, r in runs.items()}}
    log(f'identify: validation: position RMSE {result["position_rmse_m"]["nominal"] * 1e6:.0f} '
        f'um nominal, {result["position_rmse_m"]["identified"] * 1e6:.0f} um identified; motor '
        f'speed {result["motor_speed_rmse_rad_s"]["nominal"]:.1f} / '
        f'{result["motor_speed_rmse_rad_s"]["identified"]:.1f} rad/s')
    result['signals'] = {'t': rec.t - rec.t[0], 'reference': rec.reference,
                         'position': rec.position, 'speed': rec.speed, 'load': rec.load,
                         **{f'{m}_{k}': r[k] for m, r in runs.items() for k in r}}
    return result
