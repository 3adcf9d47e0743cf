"""QFT design specification (config/qft_spec.yaml): schema and typed view (thesis 4.3.2, Table 4.5, 4.8)."""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..config.params import Param, ParamError, Schema, load

S = 'spec.'
QFT_SPEC_SCHEMA = Schema('design_qft', [
    # Table 4.5 uncertainty (multipliers of the nominal value of config/plant.yaml) and the
    # sizes of the log-spaced grids: 5*2*3*3*3 = 270 plants
    Param('family.C_eq_range', 'float[]', '', [0.1, 10.0], 1e-3, 1e3, min_len=2,
          doc='C_p, C_c, C_r scaled together'),
    Param('family.C_eq_n', 'int', '', 5, 1, 50),
    Param('family.D_p_range', 'float[]', '', [0.8, 1.0], 0.1, 10.0, min_len=2),
    Param('family.D_p_n', 'int', '', 2, 1, 50),
    Param('family.beta_range', 'float[]', '', [0.7, 1.4], 0.1, 10.0, min_len=2,
          doc='x 1.379e9 Pa (Table 4.5\'s 1.379e7 is a typo)'),
    Param('family.beta_n', 'int', '', 3, 1, 50),
    Param('family.k_T_range', 'float[]', '', [0.8, 1.2], 0.1, 10.0, min_len=2,
          doc='x 0.73 Nm/A'),
    Param('family.k_T_n', 'int', '', 3, 1, 50),
    Param('family.k_E_range', 'float[]', '', [0.8, 1.2], 0.1, 10.0, min_len=2,
          doc='x 0.53 V/(rad/s)'),
    Param('family.k_E_n', 'int', '', 3, 1, 50,
          doc='grid sizes C_eq, D_p, beta, k_T, k_E: 5*2*3*3*3 = 270 plants'),
    Param('family.nominal_scale', 'float[]', '', [1.0, 1.0, 1.0, 1.0, 1.0], 1e-3, 1e3, min_len=5,
          doc='nominal plant P0 = plant.yaml values times [C_eq, D_p, beta, k_T, k_E]'),
    Param('bounds.phase_step_deg', 'float', 'deg', 5.0, 0.1, 30.0,
          doc='phase grid -360:step:0 deg (Table 4.7)'),
    # velocity loop, eqs. 4.52, 4.58, 4.65, 4.68-4.70: G_v of eq. 4.65 on omega/i_ref
    # (eq. 3.35, speed output)
    Param('velocity.Ws', 'float', '', 1.16, 1.0001, 10.0,
          doc='eq. 4.52 (PM ~ 51 deg, GM ~ 5.3 dB)'),
    Param('velocity.freqs', 'float[]', 'rad/s', [0.01, 0.1, 20.0, 200.0, 300.0, 500.0],
          1e-6, 1e6, doc='design frequencies, sec. 4.3.2'),
    Param('velocity.sens_corner', 'float', 'rad/s', 600.0, 1e-3, 1e6,
          doc='S^v(s) = (s/w)/(s/w + 1), eq. 4.58 as corrected in DESIGN.md'),
    Param('velocity.effort_w_min', 'float', 'rad/s', 200.0, 0.0, 1e6,
          doc='eq. 4.69 soft term applies at design frequencies >= this (i = 4..6: 200, 300, '
              '500 rad/s)'),
    Param('velocity.Tg_db', 'float', 'dB', 2.0, 0.0, 100.0, doc='T_g of eq. 4.69'),
    Param('velocity.K_min', 'float[]', '', [0.01, 1.0, 100.0], 1e-9, 1e9, min_len=3,
          doc='PSO box, lower limits of K1 [Nm/(rad/s)], K2 [Nm/rad], K3 [rad/s]'),
    Param('velocity.K_max', 'float[]', '', [10.0, 2000.0, 20000.0], 1e-9, 1e9, min_len=3),
    Param('velocity.iterations', 'int', '', 50, 1, 10000, doc='Table 4.8'),
    # position loop, eqs. 4.51, 4.57, 4.59-4.63, 4.74, 4.75: G of eq. 4.74 on the
    # closed-velocity-loop family x/omega_ref
    Param('position.Ws', 'float', '', 1.305, 1.0001, 10.0, doc='eq. 4.51'),
    Param('position.stab_freqs', 'float[]', 'rad/s',
          [0.001, 0.01, 0.1, 1.0, 10.0, 20.0, 50.0, 100.0, 500.0], 1e-6, 1e6),
    Param('position.sens_freqs', 'float[]', 'rad/s', [0.1, 1.0, 10.0, 20.0, 50.0, 100.0], 1e-6, 1e6),
    Param('position.sens_corner', 'float', 'rad/s', 30.0, 1e-3, 1e6,
          doc='S(s) = (s/w)/(s/w + 1), eq. 4.57'),
    Param('position.stiff_freqs', 'float[]', 'rad/s', [1.0, 10.0, 30.0, 50.0], 1e-6, 1e6),
    Param('position.M_gain', 'float', 'm/N', 2.0e-6, 1e-15, 1.0,
          doc='M(s) = M_gain (s + M_zero)^2/(s + M_pole)^2, eq. 4.60 (2e-6: >= 49 kN/mm)'),
    Param('position.M_zero', 'float', 'rad/s', 600.0, 1e-3, 1e7),
    Param('position.M_pole', 'float', 'rad/s', 6000.0, 1e-3, 1e7),
    Param('position.track_freqs', 'float[]', 'rad/s', [0.01, 0.1, 1.0, 10.0, 30.0, 50.0], 1e-6, 1e6),
    Param('position.a_up', 'float', 'rad/s', 30.0, 1e-3, 1e6,
          doc='T_up of eq. 4.62: a_up, zeta_up, w_n = wn_factor a_up / zeta_up'),
    Param('position.zeta_up', 'float', '', 0.8, 0.01, 10.0),
    Param('position.wn_factor', 'float', '', 1.25, 0.01, 100.0, doc='w_n = factor a_up / zeta'),
    Param('position.low_pole', 'float', 'rad/s', 85.0, 1e-3, 1e6,
          doc='T_low = 1/(1 + s/low_pole)^2, eq. 4.63'),
    Param('position.track_tol_db', 'float', 'dB', 0.05, 0.0, 10.0,
          doc='numerical tolerance on T_low/T_up (choice): below 0.1 rad/s |T_up|/|T_low| is '
              '< 1e-4 dB and a double-integrator loop overshoots 1 by micro-dB'),
    Param('position.K', 'float', '(rad/s)/(m s)', 165200.0, 1e-3, 1e12,
          doc='preselected gain of eq. 4.74 (thesis scaling factor 165200)'),
    Param('position.zp_min', 'float', 'rad/s', 0.5, 1e-6, 1e7,
          doc='PSO range of z_i, p_i; 0.5 rad/s keeps closed-loop tails below ~2 s'),
    Param('position.zp_max', 'float', 'rad/s', 1000.0, 1e-6, 1e7,
          doc='PSO range of z_i, p_i; must be <= pi/(2 digital.Ts) (realisable at Ts)'),
    Param('position.pairs', 'int', '', 3, 1, 10, doc='zero/pole pairs of eq. 4.74 (thesis: 3)'),
    Param('position.biquads', 'int', '', 0, 0, 4,
          doc='extra second-order sections (s^2/wz^2 + 2 zeta_z s/wz + 1)/(s^2/wp^2 + 2 zeta_p '
              's/wp + 1) in G (choice beyond eq. 4.74; thesis: 0)'),
    Param('position.zeta_min', 'float', '', 0.5, 0.01, 10.0,
          doc='range of the sections\' damping ratios; >= 0.5 keeps the controller free of '
              'resonant poles (a second loop crossover: 0.3 gave one near 1.4 krad/s)'),
    Param('position.zeta_max', 'float', '', 1.0, 0.01, 10.0),
    Param('position.effort_freqs', 'float[]', 'rad/s', [100.0, 500.0], 1e-6, 1e6,
          doc='eq. 4.75 soft control-effort frequencies (k..l)'),
    Param('position.m1', 'float', '', 1.0, 0.0, 1e9,
          doc='hard-constraint weight, eq. 4.75 (per dB of bound violation)'),
    Param('position.m2', 'float', '', 0.02, 0.0, 1e9,
          doc='soft effort weight, eq. 4.75 (per dB of |L0| at effort_freqs)'),
    Param('position.iterations', 'int', '', 100, 1, 10000, doc='Table 4.8'),
    # PSO, Table 4.8
    Param('pso.particles', 'int', '', 49, 2, 10000),
    Param('pso.W', 'float', '', 0.9, 0.0, 2.0),
    Param('pso.C1', 'float', '', 2.0, 0.0, 10.0),
    Param('pso.C2', 'float', '', 2.0, 0.0, 10.0),
    Param('pso.v_max_frac', 'float', '', 0.2, 1e-3, 1.0,
          doc='velocity clamp as fraction of the (log10) range (choice); W=0.9, C=2 diverges '
              'unclamped'),
    Param('pso.stability_penalty', 'float', '', 1000.0, 0.0, 1e12,
          doc='added when any family member has a closed-loop eigenvalue with Re >= 0'),
    Param('pso.Ws_weight', 'float', '', 10.0, 0.0, 1e9,
          doc='eq. 4.70 weight per dB of max|T| over W_s on the family'),
    # prefilter, eq. 4.61, 4.77: F(s) = (s/a + 1)/((s/b + 1)(s/c + 1)), the eq. 4.77 structure
    Param('prefilter.w_max', 'float', 'rad/s', 50.0, 1e-3, 1e6,
          doc='tracking band checked on a dense grid from min(track_freqs) to this'),
    Param('prefilter.bandwidth_min_hz', 'float', 'Hz', 9.0, 0.0, 1e4,
          doc='required -3 dB bandwidth of F T on the nominal plant'),
    Param('prefilter.corner_min', 'float', 'rad/s', 5.0, 1e-3, 1e6),
    Param('prefilter.corner_max', 'float', 'rad/s', 2000.0, 1e-3, 1e7),
    # digital implementation (controller at Ts in the ROS stack)
    Param('digital.Ts', 'float', 's', 0.001, 1e-6, 1.0,
          doc='controller sample period (SIL tick, plant.sim.Ts)'),
    Param('digital.delay', 'float', 's', -1.0, -1.0, 1.0,
          doc='position-loop delay T_d; < 0: derived, 1.5 Ts + plant.drive.delay (= 2.5 ms; '
              'one sample compute-to-apply, ZOH ~ Ts/2, drive FIFO)'),
    Param('digital.prewarp_w', 'float', 'rad/s', 0.0, 0.0, 1e6,
          doc='Tustin prewarp frequency of G and F in the digital check (0: none, as the node)'),
    Param('digital.step', 'float', 'm', 0.005, 1e-6, 1.0,
          doc='step of the step-response check (F T, discrete)'),
    Param('digital.overshoot_max_pct', 'float', '%', 5.0, 0.0, 100.0),
    Param('digital.settling_max', 'float', 's', 0.3, 1e-3, 100.0, doc='2 % settling time limit'),
    Param('digital.settling_band', 'float', '', 0.02, 1e-4, 0.5),
    Param('digital.horizon', 'float', 's', 2.0, 0.01, 100.0, doc='step simulation length'),
    Param('digital.agree_db', 'float', 'dB', 1.0, 0.0, 100.0,
          doc='allowed |discrete - continuous-with-delay| of max|T| and GM (nominal)'),
    Param('digital.agree_deg', 'float', 'deg', 5.0, 0.0, 180.0,
          doc='allowed |discrete - continuous-with-delay| of PM (nominal)'),
    # verification
    Param('verify.w_min', 'float', 'rad/s', 0.01, 1e-6, 1e6),
    Param('verify.w_max', 'float', 'rad/s', 3000.0, 1e-6, 1e7,
          doc='top of the dense grid; 3000 rad/s is just below pi/Ts at 1 kHz'),
    Param('verify.n_points', 'int', '', 400, 10, 100000),
    Param('verify.band_max_hz', 'float', 'Hz', 7.0, 1e-3, 1e4,
          doc='sensitivity and stiffness checked up to this frequency'),
])


@dataclass(frozen=True)
class QftSpec:
    """Typed view of the validated spec dictionary (all frequencies in rad/s)."""

    values: dict

    def __getitem__(self, key):
        return self.values[key]

    def arr(self, key) -> np.ndarray:
        return np.asarray(self.values[key], float)

    @property
    def velocity_freqs(self) -> np.ndarray:
        return np.unique(self.arr('velocity.freqs'))

    @property
    def position_freqs(self) -> np.ndarray:
        return np.unique(np.concatenate([self.arr(k) for k in (
            'position.stab_freqs', 'position.sens_freqs', 'position.stiff_freqs',
            'position.track_freqs')]))

    # specification transfer functions, evaluated at s = j w
    def S_v(self, w):
        """Eq. 4.58 (corrected): S^v(s) = (s/w_c)/(s/w_c + 1)."""
        s = 1j * np.asarray(w, float) / self['velocity.sens_corner']
        return s / (s + 1)

    def S_p(self, w):
        """Eq. 4.57: S(s) = (s/30)/(s/30 + 1)."""
        s = 1j * np.asarray(w, float) / self['position.sens_corner']
        return s / (s + 1)

    def M(self, w):
        """Eq. 4.60: M(s) = 2e-6 (s + 600)^2 / (s + 6000)^2 (m/N)."""
        s = 1j * np.asarray(w, float)
        return self['position.M_gain'] * (s + self['position.M_zero']) ** 2 / \
            (s + self['position.M_pole']) ** 2

    def T_up(self, w):
        """Eq. 4.62: (s/a_up + 1)/(s^2/w_n^2 + 2 zeta s/w_n + 1), w_n = 1.25 a_up/zeta."""
        s = 1j * np.asarray(w, float)
        a, z = self['position.a_up'], self['position.zeta_up']
        wn = self['position.wn_factor'] * a / z
        return (s / a + 1) / (s ** 2 / wn ** 2 + 2 * z * s / wn + 1)

    def loop_delay(self, drive_delay: float) -> float:
        """Position-loop delay T_d [s]: digital.delay if >= 0, else 1.5 Ts + plant.drive.delay."""
        d = self['digital.delay']
        return float(d) if d >= 0 else 1.5 * self['digital.Ts'] + float(drive_delay)

    def delay_samples(self, drive_delay: float) -> int:
        """Shift states of the discrete loop: compute-to-apply sample + drive FIFO."""
        return int(round(float(drive_delay) / self['digital.Ts'])) + 1

    def T_low(self, w):
        """Eq. 4.63: 1/(1 + s/85)^2."""
        s = 1j * np.asarray(w, float)
        return 1.0 / (1 + s / self['position.low_pole']) ** 2


def check(vals: dict) -> None:
    """Range pairs: each family.*_range [min, max] with min <= max; velocity.K_min < K_max (3
    values each); position.zp_min < zp_max <= pi/(2 digital.Ts); position.zeta_min < zeta_max;
    prefilter.corner_min < corner_max; verify.w_min < w_max."""
    for key in ('family.C_eq_range', 'family.D_p_range', 'family.beta_range',
                'family.k_T_range', 'family.k_E_range'):
        if len(vals[key]) != 2 or vals[key][0] > vals[key][1]:
            raise ParamError(f'{key} = {vals[key]!r}: expected [min, max] with min <= max', key)
    lo, hi = 'velocity.K_min', 'velocity.K_max'
    if len(vals[lo]) != 3 or len(vals[hi]) != 3 or any(a >= b for a, b in zip(vals[lo], vals[hi])):
        raise ParamError(f'{lo}/{hi} = {vals[lo]!r}/{vals[hi]!r}: expected 3 values each '
                         f'with min < max', lo)
    for lo, hi in (('position.zp_min', 'position.zp_max'),
                   ('position.zeta_min', 'position.zeta_max'),
                   ('prefilter.corner_min', 'prefilter.corner_max'),
                   ('verify.w_min', 'verify.w_max')):
        if vals[lo] >= vals[hi]:
            raise ParamError(f'{lo} = {vals[lo]!r}: expected < {hi} ({vals[hi]!r})', lo)
    nyq2 = np.pi / (2 * vals['digital.Ts'])
    if vals['position.zp_max'] > nyq2:
        raise ParamError(f'position.zp_max = {vals["position.zp_max"]!r}: expected <= '
                         f'pi/(2 digital.Ts) = {nyq2:.6g} rad/s (not realisable at Ts = '
                         f'{vals["digital.Ts"]:g} s)', 'position.zp_max')


QFT_SPEC_SCHEMA.check = check


def load_spec(path: str) -> QftSpec:
    """Load and validate a qft_spec.yaml (ROS params file, node ``design_qft``)."""
    vals = load(QFT_SPEC_SCHEMA, [path])
    return QftSpec(vals)


def default_spec() -> QftSpec:
    """The schema defaults: the thesis' specification (Table 4.5, eqs. 4.58-4.61) with the
    thesis' controller structure; the shipped design's choices (K, zp_max, biquads) are
    config/qft_spec.yaml's, read by :func:`configured_spec`."""
    return QftSpec(QFT_SPEC_SCHEMA.validate({}))


def configured_spec(config_dir: str | None = None) -> QftSpec:
    """config/qft_spec.yaml if present, else the schema defaults (the thesis spec)."""
    from ..config.params import default_config_dir
    path = os.path.join(config_dir or default_config_dir(), 'qft_spec.yaml')
    return load_spec(path) if os.path.isfile(path) else default_spec()
