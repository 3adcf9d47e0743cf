"""Parameters of the experiment node (experiment.*, config/experiment.yaml) plus the shared
plant.* set (config/plant.yaml: Ts, stroke, speed and current limits, A_p, D_p)."""
from __future__ import annotations

import math

from ..config.params import Param, ParamError, Schema
from ..plant.parameters import PLANT_SCHEMA
from .experiments import KINDS, PREFIX as E

RPM_1000 = 1000 * math.pi / 30          # [rad/s] the thesis' drive sweep amplitude (sec. 3.6.1)

NODE = Schema('experiment', [
    Param(E + 'kind', 'str', '', 'validation', choices=KINDS,
          doc='drive: speed sines on eha/command (no controller); friction: position sines; '
              'leakage: held loads; validation: a step and a sine (docs/identification.md)'),
    Param(E + 'plant_side', 'str', '', 'sim', choices=('sim', 'bridge'),
          doc='what the run drives, written into eha/experiment (plant_sim or a drive behind '
              'hardware_bridge)'),
    Param(E + 'lead_ticks', 'int', '', 2, 1, 100,
          doc='references and loads are sent this many ticks ahead, stamped with their tick'),
    Param(E + 'start_delay', 'float', 's', 1.0, 0.0, 600.0,
          doc='wait this long after the loop runs (plant side active) before the plan starts'),
    Param(E + 'start_after', 'str[]', '', [''], min_len=1,
          doc='the plan also waits until these nodes subscribe to every /eha topic with a '
              'publisher and report each publisher matched (their ~/matched; run_stack '
              '--record adds the recorder; after 30 s it starts anyway, with a warning); '
              'empty string = none'),
    Param(E + 'abort_error', 'float', 'm', 0.005, 1e-5, 0.12,
          doc='closed loop: stop when |reference - estimate| stays above this'),
    Param(E + 'abort_ticks', 'int', '', 20, 1, 100000, doc='... for this many ticks in a row'),
    Param(E + 'stroke_margin', 'float', 'm', 0.005, 0.0, 0.05,
          doc='plans, and the measured position (else the run stops), stay this far inside '
              'the end stops'),
    Param(E + 'exit_when_done', 'bool', '', True,
          doc='the node exits when the plan is done (once every subscriber acknowledged its '
          'last samples, 3 s at most)'),
    Param(E + 'diagnostics_period', 'float', 's', 1.0, 0.05, 60.0, doc='/diagnostics period'),
    Param(E + 'drive.freqs', 'float[]', 'Hz', [1.0, 2.0, 3.0, 5.0, 7.0, 10.0, 15.0], 0.01,
          1000.0, doc='speed-reference sweep of the velocity loop: speed sines, one after the '
                      'other (thesis Fig. 3.36: 1-15 Hz)'),
    Param(E + 'drive.amplitude', 'float', 'rad/s', RPM_1000, 0.1, 2000.0,
          doc='speed sine amplitude (thesis: 1000 rpm)'),
    Param(E + 'drive.periods', 'int', '', 6, 1, 10000, doc='periods per frequency'),
    Param(E + 'drive.relax', 'float', 's', 0.3, 0.0, 60.0, doc='zero speed between sines'),
    Param(E + 'drive.position_bandwidth', 'float', 'Hz', 0.1, 0.001, 10.0,
          doc='the slow proportional loop on the measured position added to the speed '
              'reference (keeps the piston in its stroke); at most the lowest sine / 5'),
    Param(E + 'friction.freqs', 'float[]', 'Hz', [0.25, 0.5, 1.0, 2.0, 3.0, 4.0, 5.0], 0.01,
          1000.0, doc='closed-loop position sines, no load, of rising frequency, so of rising '
                      'piston speed (Fig. 3.40; 5 mm up to 5 Hz: 157 mm/s); the fit needs '
                      'speeds past the ringing of the Stribeck fall'),
    Param(E + 'friction.amplitude', 'float', 'm', 0.005, 1e-5, 0.1,
          doc='position sine amplitude'),
    Param(E + 'friction.periods', 'int', '', 3, 1, 10000, doc='periods per frequency'),
    Param(E + 'friction.relax', 'float', 's', 0.5, 0.0, 60.0,
          doc='reference held at 0 between sines'),
    Param(E + 'leakage.loads', 'float[]', 'N', [5000.0, 10000.0, -5000.0, -10000.0],
          -2e5, 2e5, doc='load levels on eha/sim/load_force in turn, reference at 0 (Fig. '
                         '3.44; F_L: + pushes towards -x)'),
    Param(E + 'leakage.hold', 'float', 's', 4.0, 0.01, 600.0,
          doc='each level held this long (the motor speed that holds it settles)'),
    Param(E + 'leakage.ramp', 'float', 's', 0.2, 0.0, 60.0, doc='ramp between levels'),
    Param(E + 'leakage.rest', 'float', 's', 1.0, 0.0, 60.0, doc='no load before and after'),
    Param(E + 'validation.step', 'float', 'm', 0.005, 1e-5, 0.1,
          doc='closed-loop step of the reference (Fig. 3.45), held, then back to 0, held'),
    Param(E + 'validation.step_hold', 'float', 's', 1.5, 0.01, 60.0,
          doc='each step held this long'),
    Param(E + 'validation.sine_hz', 'float', 'Hz', 1.0, 0.01, 1000.0,
          doc='frequency of the closed-loop sine (Fig. 3.45)'),
    Param(E + 'validation.sine_amplitude', 'float', 'm', 0.005, 1e-5, 0.1,
          doc='amplitude of the sine'),
    Param(E + 'validation.sine_periods', 'int', '', 4, 1, 10000, doc='periods of the sine'),
    Param(E + 'validation.rest', 'float', 's', 0.5, 0.0, 60.0,
          doc='reference at 0 before the step and around the sine'),
])


def check(p: dict) -> None:
    """The node refuses an experiment beyond the actuator's limits (experiments.build's
    UsageError): the same line here."""
    from ..config.cli import UsageError
    from .experiments import build
    try:
        build(p)
    except UsageError as err:
        raise ParamError(str(err)) from None


SCHEMA = PLANT_SCHEMA + Schema('experiment', NODE.params, check)
