"""Benchmark of the QFT bound computation (270 plants x 9 frequencies x 73 phases, all specs)
and of the batched state-space frequency response. Flat keys, seconds."""
from __future__ import annotations

import time

import numpy as np


def run(args=None) -> dict:
    from ..core.config.params import load
    from ..core.plant.parameters import PLANT_SCHEMA
    from ..core.qft import bounds as qb
    from ..core.controller import lti
    from ..core.qft import family
    from ..core.qft.spec import default_spec
    from ..core.config.params import default_config_dir
    import os
    plant = load(PLANT_SCHEMA, [os.path.join(default_config_dir(), 'plant.yaml')])
    spec = default_spec()
    fam = family.build_family(plant, spec)
    casc = family.velocity_loop_plants(fam, lti.thesis_velocity(fam.k_T_nominal))
    w9 = np.asarray(spec['position.stab_freqs'], float)          # the 9 stability frequencies
    wall = spec.position_freqs
    out = {'plants': fam.n, 'phases': 73, 'freqs_bench': len(w9)}
    reps = 3
    t = time.perf_counter()
    for _ in range(reps):
        casc.P_omega(wall), casc.P_d(wall)
    out['freqresp_s'] = (time.perf_counter() - t) / reps
    out['freqresp_evals'] = int(2 * (fam.n + 1) * len(wall))
    wd = np.logspace(-2, 3, 400)
    t = time.perf_counter()
    casc.P_omega(wd)
    out['freqresp_dense_400_s'] = time.perf_counter() - t

    def full(w):
        # every spec evaluated at every one of the given frequencies (worst case)
        vals = dict(spec.values)
        for k in ('position.stab_freqs', 'position.sens_freqs', 'position.stiff_freqs',
                  'position.track_freqs'):
            vals[k] = list(w)
        sp = type(spec)(vals)
        return qb.position_bounds(sp, casc.P_omega, casc.P_d, w=np.asarray(w))

    t = time.perf_counter()
    for _ in range(reps):
        full(w9)
    out['bounds_all_specs_9freq_s'] = (time.perf_counter() - t) / reps
    t = time.perf_counter()
    for _ in range(reps):
        qb.position_bounds(spec, casc.P_omega, casc.P_d)
    out['bounds_thesis_spec_s'] = (time.perf_counter() - t) / reps
    out['freqs_thesis_spec'] = len(wall)
    return out


if __name__ == '__main__':
    import json
    print(json.dumps(run(), indent=1))
