"""The position sensor's error bands from its model (plant.sensors.*: white sigma, Gauss-Markov
sigma and corner, Fig. 4.6): the offset state's projection bound, the monitor's DISAGREE band
and the fault detector's jump step (issue 15; derived, not tuned: a sensor identified on the
bench moves them with it).

The Gauss-Markov offset b gives about T_OP 2 pi f_c independent samples per plant in T_OP s;
over N_PLANTS plants at NOISE_SCALE times the datasheet's noise, a two-sided false-alarm
probability P_FA over all of them needs the band at z sigma, z = Phi^-1(P_FA / (2 n)).
- offset bound: b projected to +-(z + 1) sigma_gm (the estimate never stays further from the
  measurement, whatever the model says);
- DISAGREE band: z sigma_d of the monitor's low-passed disagreement z - x_hat, sigma_d^2 =
  sigma_gm^2 + sigma_w^2 alpha / (2 - alpha) (b plus the low-passed white noise; alpha the
  low-pass's per-tick weight at estimator.monitor.lowpass);
- jump step: a jump moves the reading within one sample, where the innovation increment of
  the white noise alone has sigma sqrt(2) sigma_w: JUMP_K times that.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

from .adapt import lowpass_alpha

NOISE_SCALE = 2.0   # a sensor may be this much noisier than its datasheet (the random box's
#                     noise max, config/campaigns/family_random.yaml)
T_OP = 60.0         # [s] of nominal operation without a false alarm ...
N_PLANTS = 270      # ... on each plant of the Table 4.5 grid
P_FA = 0.01         # two-sided false-alarm probability over all of them
JUMP_K = 5.0        # sigmas of the white noise's own step that make a jump


@dataclass(frozen=True)
class SensorBands:
    """The bands of one sensor model (SI)."""

    z: float                # the bands' number of sigmas
    offset_bound: float     # [m] |b| projection bound
    band: float             # [m] monitor DISAGREE band
    jump_step: float        # [m] fault detector's least jump step


def sensor_bands(position_sigma: float, gm_sigma: float, gm_corner: float, Ts: float,
                 monitor_lowpass: float) -> SensorBands:
    """The bands (module doc) of a position sensor with white sigma ``position_sigma`` [m] and
    Gauss-Markov sigma ``gm_sigma`` [m], corner ``gm_corner`` [Hz], sampled at ``Ts`` [s], its
    disagreement low-passed at ``monitor_lowpass`` [Hz]."""
    s_gm, s_w = NOISE_SCALE * gm_sigma, NOISE_SCALE * position_sigma
    n = T_OP * 2.0 * math.pi * gm_corner * N_PLANTS
    z = -NormalDist().inv_cdf(P_FA / (2.0 * n))
    alpha = lowpass_alpha(monitor_lowpass, Ts)
    s_d = math.sqrt(s_gm ** 2 + s_w ** 2 * alpha / (2.0 - alpha))
    return SensorBands(z=z, offset_bound=(z + 1.0) * s_gm, band=z * s_d,
                       jump_step=JUMP_K * math.sqrt(2.0) * s_w)


def from_params(p: dict) -> SensorBands:
    """The bands of the sensor model in parameters ``p`` (plant.sensors.*, plant.sim.Ts,
    estimator.monitor.lowpass)."""
    s = 'plant.sensors.'
    return sensor_bands(p[s + 'position_sigma'], p[s + 'position_gm_sigma'],
                        p[s + 'position_gm_corner'], p['plant.sim.Ts'],
                        p['estimator.monitor.lowpass'])
