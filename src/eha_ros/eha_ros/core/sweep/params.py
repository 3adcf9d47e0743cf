"""Parameters of the sweep node (sweep.*) plus the shared plant.* set."""
from __future__ import annotations

from ..config.params import Param, ParamError, Schema
from ..plant.parameters import PLANT_SCHEMA

NODE = Schema('sweep', [
    Param('sweep.mode', 'str', '', 'stepped',
          choices=('stepped', 'chirp', 'step', 'stiffness', 'load_step'),
          doc='stiffness: stepped sine of the external load force, reference held at the '
              'offset; load_step: a step of the load force at 0.5 s, reference held'),
    Param('sweep.amplitude', 'float', 'm', 1e-3, 1e-6, 0.12,
          doc='sine/chirp amplitude or step size (1 mm: thesis Fig. 4.51)'),
    Param('sweep.offset', 'float', 'm', 0.0, -0.12, 0.12, doc='position the signal is centred on'),
    Param('sweep.start_hz', 'float', 'Hz', 1.0, 0.01, 1000.0, doc='Fr_Test starting_freq'),
    Param('sweep.increment_hz', 'float', 'Hz', 1.0, 1e-3, 1000.0, doc='Fr_Test freq_increment'),
    Param('sweep.max_hz', 'float', 'Hz', 50.0, 0.01, 1000.0,
          doc='Fr_Test max_freq (at most Nyquist/10: 50 Hz at 1 kHz)'),
    Param('sweep.max_accel', 'float', 'm/s^2', 5.0, 0.01, 1000.0,
          doc='stepped: amplitude lowered to max_accel/(2 pi f)^2 where the sine would '
              'accelerate more (1 mm: above ~11 Hz); below the controller\'s reference '
              'accel_limit (6): a faster sine measures the reference shaper'),
    Param('sweep.stop_at_bandwidth', 'bool', '', True,
          doc='stepped: stop after the first frequency below -3 dB (the bandwidth is bracketed)'),
    Param('sweep.periods', 'int', '', 8, -1000, 10000, doc='Fr_Test period_count'),
    Param('sweep.settle_periods', 'int', '', 2, 0, 100,
          doc='periods skipped by the analysis (appendix B.2)'),
    Param('sweep.relax_s', 'float', 's', 0.3, -100.0, 60.0, doc='Fr_Test freq_interval (rest)'),
    Param('sweep.load_amplitude', 'float', 'N', 5000.0, 1.0, 200000.0,
          doc='stiffness, load_step: load force amplitude (step size) on eha/sim/load_force'),
    Param('sweep.stiffness_freqs', 'float[]', 'Hz', [1.0, 4.0, 7.0], 0.01, 1000.0, min_len=1,
          doc='stiffness: load frequencies (eq. 4.60 is checked up to 7 Hz)'),
    Param('sweep.chirp_f0', 'float', 'Hz', 0.5, 0.01, 1000.0, doc='chirp start frequency'),
    Param('sweep.chirp_f1', 'float', 'Hz', 20.0, 0.01, 1000.0, doc='chirp end frequency'),
    Param('sweep.chirp_duration', 'float', 's', 30.0, 0.1, 3600.0, doc='chirp length'),
    Param('sweep.chirp_fade', 'float', 's', 0.5, 0.0, 60.0,
          doc='raised-cosine fade in and out of the chirp'),
    Param('sweep.step_duration', 'float', 's', 2.0, 0.05, 3600.0, doc='step test length'),
    Param('sweep.load_step_duration', 'float', 's', 5.5, 0.05, 3600.0,
          doc='load_step: run length; at least the step (0.5 s) plus the end of the steady '
              'window (4.5 s after it); 0.5 s more covers a load that reaches the plant late'),
    Param('sweep.lead_ticks', 'int', '', 2, 1, 100,
          doc='references are sent this many ticks ahead, stamped with their tick'),
    Param('sweep.start_delay', 'float', 's', 1.0, 0.0, 600.0,
          doc='wait this long after state and command streams are up'),
    Param('sweep.abort_error', 'float', 'm', 0.005, 1e-5, 0.12,
          doc='abort when |reference - estimate| stays above this'),
    Param('sweep.abort_ticks', 'int', '', 20, 1, 100000,
          doc='... for this many ticks in a row'),
    Param('sweep.output', 'str', '', 'auto', choices=('auto', 'truth', 'estimate', 'measured'),
          doc='signal analysed against the reference (auto: truth when present)'),
    Param('sweep.out_dir', 'str', '', 'out', doc='runs are written under out_dir/<run>/'),
    Param('sweep.run_name', 'str', '', '', doc='folder name; empty = timestamp'),
    Param('sweep.controller_file', 'str', '', '',
          doc='controller YAML for the model overlay; empty = config/controller.yaml'),
    Param('sweep.exit_when_done', 'bool', '', True,
          doc='the node exits when the sweep is finished (once every subscriber '
          'acknowledged its last samples, 3 s at most)'),
])



def build_plan(p: dict):
    """The signal plan from validated parameters; one-line UsageError for unusable values."""
    from .signals import (Chirp, Step, SteppedSine, check_limits, check_load_step,
                          check_sweep)
    Ts = p['plant.sim.Ts']
    stroke = p['plant.cylinder.stroke']
    if p['sweep.mode'] == 'stepped':
        check_sweep(p['sweep.start_hz'], p['sweep.increment_hz'], p['sweep.max_hz'],
                    p['sweep.periods'], p['sweep.relax_s'], p['sweep.amplitude'],
                    p['sweep.offset'], stroke, Ts, settle_periods=p['sweep.settle_periods'])
        return SteppedSine(p['sweep.start_hz'], p['sweep.increment_hz'], p['sweep.max_hz'],
                           p['sweep.periods'], p['sweep.relax_s'], p['sweep.amplitude'],
                           p['sweep.offset'], Ts, max_accel=p['sweep.max_accel'])
    if p['sweep.mode'] == 'stiffness':
        freqs = list(p['sweep.stiffness_freqs'])
        check_sweep(min(freqs), 1.0, max(freqs), p['sweep.periods'], p['sweep.relax_s'],
                    p['sweep.amplitude'], p['sweep.offset'], stroke, Ts,
                    settle_periods=p['sweep.settle_periods'])
        return SteppedSine(0.0, 0.0, 0.0, p['sweep.periods'], p['sweep.relax_s'],
                           p['sweep.load_amplitude'], 0.0, Ts, tuple(freqs))
    if p['sweep.mode'] == 'load_step':
        from .analysis import LOAD_STEP
        t_step, window = LOAD_STEP['t_step'], LOAD_STEP['steady']
        check_load_step(p['sweep.load_step_duration'], t_step, window[1], p['sweep.offset'],
                        stroke)
        return Step(p['sweep.load_amplitude'], p['sweep.load_step_duration'], t_step, 0.0, Ts)
    if p['sweep.mode'] == 'chirp':
        check_limits(p['sweep.chirp_f1'], p['sweep.amplitude'], p['sweep.offset'], stroke, Ts)
        return Chirp(p['sweep.chirp_f0'], p['sweep.chirp_f1'], p['sweep.chirp_duration'],
                     p['sweep.amplitude'], p['sweep.offset'], p['sweep.chirp_fade'], Ts)
    check_limits(0.0, p['sweep.amplitude'], p['sweep.offset'], stroke, Ts)
    return Step(p['sweep.amplitude'], p['sweep.step_duration'], 0.1, p['sweep.offset'], Ts)


def check(p: dict) -> None:
    """The node refuses a sweep it cannot run (build_plan's UsageError): the same line here."""
    from ..config.cli import UsageError
    try:
        build_plan(p)
    except UsageError as err:
        raise ParamError(str(err)) from None


SCHEMA = PLANT_SCHEMA + Schema('sweep', NODE.params, check)
