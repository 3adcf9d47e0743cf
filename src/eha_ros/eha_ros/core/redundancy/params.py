"""Parameters of the switch_manager node: switch.* (config/switch_manager.yaml) plus the shared
plant.* set (config/plant.yaml: Ts, valve opening time, current limit, k_T, D_p, J_eq, b_eq)."""
from __future__ import annotations

from ..config.params import Param, Schema, _chain
from ..plant.parameters import PLANT_SCHEMA

S = 'switch.'
H = S + 'health.'


def _monitor(name: str, unit: str, trip: float, clear: float, trip_time: float,
             clear_time: float, hi: float, what: str) -> list[Param]:
    """trip/clear levels (hysteresis) and trip/clear persistence times (debounce)."""
    return [
        Param(f'{H}{name}.enabled', 'bool', '', True, doc=f'use the {what} monitor'),
        Param(f'{H}{name}.trip', 'float', unit, trip, 0.0, hi,
              doc=f'{what}: unhealthy above this level'),
        Param(f'{H}{name}.clear', 'float', unit, clear, 0.0, hi,
              doc=f'{what}: healthy again below this level (hysteresis, <= trip)'),
        Param(f'{H}{name}.trip_time', 'float', 's', trip_time, 0.0, 10.0,
              doc=f'{what}: above trip this long before it counts (debounce)'),
        Param(f'{H}{name}.clear_time', 'float', 's', clear_time, 0.0, 60.0,
              doc=f'{what}: below clear this long before it recovers'),
    ]


NODE = Schema('switch_manager', [
    Param(S + 'initial_channel', 'int', '', 0, 0, 1,
          doc='couple that drives at start: 0 = A, 1 = B'),
    Param(S + 'prespin_time', 'float', 's', 0.05, 0.0, 1.0,
          doc='commanded switch: the new drive runs with its valves closed at most this long '
              'first (sooner: prespin_match)'),
    Param(S + 'prespin_match', 'float', 'rad/s', 20.0, 0.0, 1000.0,
          doc='commanded switch: the new couple\'s valves open as soon as its drive reports '
              'enabled and its measured speed is within this of the old couple\'s, so the '
              'flow is handed over at one speed (0: always wait prespin_time)'),
    Param(S + 'fault_prespin_time', 'float', 's', 0.0, 0.0, 1.0,
          doc='automatic switch: the same, usually 0 (isolate the faulty couple at once)'),
    Param(S + 'valve_margin', 'float', 's', 0.005, 0.0, 1.0,
          doc='wait after the valve opening time (plant.valves.onoff_time, 20 ms) before the old '
              'drive is disabled and the switch is complete'),
    Param(S + 'blank_time', 'float', 's', 0.05, 0.0, 5.0,
          doc='speed/pressure/estimator monitors of a couple ignore this long after it '
              'starts or stops driving'),
    Param(S + 'min_dwell', 'float', 's', 0.5, 0.0, 60.0,
          doc='minimum time between two automatic switches'),
    Param(S + 'latch_failed', 'bool', '', True,
          doc='a couple switched away from for a fault stays failed until a commanded switch '
              'to it (when its monitors are healthy again)'),
    Param(S + 'safe_mode', 'str', '', 'hold', choices=('hold', 'bypass'),
          doc='both couples failed: hold = drives off, all valves closed (hydraulic lock); '
              'bypass = drives off, pump valves closed, A-B bypass open (damped, free)'),
    *_monitor('drive', '', 0.5, 0.5, 0.002, 0.5, 1.0,
              'drive status (fault flag, or enable not as commanded)'),
    Param(H + 'drive.enable_grace', 'float', 's', 0.2, 0.0, 5.0,
          doc='time a drive may take to first report a newly commanded enable state; once '
              'reported, any difference is a fault. The drive monitor: status flags (0/1) '
              'above trip are bad; trip_time 2 ms = 3 consecutive samples at 1 kHz; a current '
              'while disabled: current.standby_max'),
    *_monitor('speed', 'rad/s', 150.0, 50.0, 0.02, 0.5, 5000.0,
              'motor-speed tracking |low-passed (reference - measured)|'),
    Param(H + 'speed.lowpass', 'float', 'Hz', 50.0, 0.1, 500.0,
          doc='low-pass corner of the speed-tracking error (drive lag is not a fault: removes '
              'the velocity-loop lag at 3 Hz); not judged while |i| >= current.clear x I_max '
              '(a current-limited drive lags). Levels: trip 150 rad/s = 1430 rpm, clear 50 '
              'rad/s = 480 rpm'),
    Param(H + 'speed.max_command_age', 'float', 's', 0.05, 0.001, 10.0,
          doc='speed, current, pressure and estimator monitors are judged only while the '
              'latest command answers a state at most this old (loop closed); the speed '
              'error is measured from the range of the references of this window (= plant_sim '
              'command_timeout: the oldest command a drive may still apply)'),
    *_monitor('current', '', 0.95, 0.8, 0.2, 0.5, 10.0,
              '|motor current| as a fraction of plant.drive.I_max'),
    Param(H + 'current.standby_max', 'float', 'A', 2.0, 0.0, 1000.0,
          doc='|current| of a disabled drive above this is a drive fault. Levels of the '
              'current monitor with I_max 36 A: trip 0.95 = 34.2 A, clear 0.8 = 28.8 A; '
              'trip_time 0.2 s: a short saturation during a step is normal'),
    *_monitor('pressure', 'Pa', 5.0e6, 2.5e6, 0.05, 0.5, 1.0e8,
              'torque balance |(k_T i - b_eq w - J_eq dw/dt)/D_p - (p_A - p_B)|'),
    Param(H + 'pressure.lowpass', 'float', 'Hz', 10.0, 0.1, 500.0,
          doc='low-pass corner of the torque-balance residual (eq. 3.17). Levels: trip 50 '
              'bar (about 3 Nm of unexplained shaft torque), clear 25 bar'),
    Param(H + 'pressure.low_side_min', 'float', 'Pa', 1.0e5, -1.0e6, 1.0e8,
          doc='plausible readings: min(p_A, p_B) (boost side) at least this, else the '
              'pressure sensors are suspect and the monitor holds its verdict'),
    Param(H + 'pressure.low_side_max', 'float', 'Pa', 4.0e6, 0.0, 1.0e8,
          doc='plausible readings: min(p_A, p_B) at most this (40 bar; accumulator 10 bar)'),
    Param(H + 'pressure.max', 'float', 'Pa', 4.0e7, 0.0, 1.0e8,
          doc='plausible readings: max(p_A, p_B) at most this (sensor range, 400 bar)'),
    *_monitor('estimator', 'm', 5.0e-4, 1.0e-4, 0.02, 0.5, 1.0,
              'estimator residual: low-passed |position innovation| of /eha/estimate'),
    Param(H + 'estimator.lowpass', 'float', 'Hz', 20.0, 0.01, 500.0,
          doc='low-pass corner of the |innovation| (driving couple only). Not the NIS: with z '
              '= [x, p_D] the NIS is dominated by the p_D model mismatch under load (~7500 at '
              '10 kN). Levels: trip 0.5 mm (nominal |innovation| ~10 um, 0.4 mm peak at the '
              'load step), clear 0.1 mm'),
    Param(S + 'node.arm_time', 'float', 's', 2.0, 0.0, 60.0,
          doc='speed, current, pressure and estimator monitors start judging once the '
              'position loop has been closed (fresh commands) this long (start-up transient)'),
    Param(S + 'node.status_period', 'float', 's', 0.2, 0.01, 10.0,
          doc='/eha/redundancy is published on change and at this period (wall time; 0.2 s: '
              '5 Hz)'),
    Param(S + 'node.diagnostics_period', 'float', 's', 1.0, 0.05, 60.0,
          doc='/diagnostics period (wall time, also in lock-step)'),
    Param(S + 'node.state_timeout', 'float', 's', 0.05, 0.001, 10.0,
          doc='no /eha/state for this long is reported on /diagnostics'),
    Param(S + 'node.log_dir', 'str', '', 'out/redundancy',
          doc='folder of the switch-event log <log_dir>/switch_events.jsonl ("" = no file)'),
    # the loop supervisor (core.loop.supervisor): any condition -> the safe state, ERROR
    Param(S + 'supervisor.stall_timeout', 'float', 's', 0.2, 0.01, 10.0,
          doc='real time: a loop stream (state, estimate, command) whose seq does not advance '
              'for this long (wall time) is a stalled node'),
    Param(S + 'supervisor.lockstep_stall_timeout', 'float', 's', 5.0, 0.1, 600.0,
          doc='lock-step: the same in wall time (a lock-step loop waits for its slowest node)'),
    Param(S + 'supervisor.start_timeout', 'float', 's', 30.0, 0.1, 600.0,
          doc='the first command must follow the first state within this (wall time)'),
    Param(S + 'supervisor.window', 'float', 's', 1.0, 0.01, 60.0,
          doc='window of the unanswered-ticks and limit-cycle checks'),
    Param(S + 'supervisor.max_unanswered', 'float', '', 0.02, 0.0, 1.0,
          doc='real time: share of the window\'s ticks without command(k) before state(k+1) '
              '(as the manager sees them)'),
    Param(S + 'supervisor.reject_time', 'float', 's', 0.05, 0.001, 10.0,
          doc='estimates in a row made without the position measurement (rejected)'),
    Param(S + 'supervisor.saturation', 'float', '', 0.95, 0.1, 1.0,
          doc='a speed command at least this share of plant.drive.omega_max is saturated'),
    Param(S + 'supervisor.cycle_share', 'float', '', 0.2, 0.0, 1.0,
          doc='limit cycle: saturated on at least this share of the window ...'),
    Param(S + 'supervisor.cycle_reversals', 'int', '', 4, 1, 10000,
          doc='... with at least this many sign reversals between saturated commands'),
])

def check(p: dict) -> None:
    """Each monitor's clear level at most its trip level (hysteresis); health.pressure's
    low_side_min at most low_side_max."""
    from ..config.params import ParamError
    for name in ('drive', 'speed', 'current', 'pressure', 'estimator'):
        trip, clear = p[f'{H}{name}.trip'], p[f'{H}{name}.clear']
        if clear > trip:
            raise ParamError(f'{H}{name}.clear = {clear!r}: expected <= {H}{name}.trip '
                             f'({trip!r}) (hysteresis)', f'{H}{name}.clear')
    lo, hi = p[H + 'pressure.low_side_min'], p[H + 'pressure.low_side_max']
    if lo > hi:
        raise ParamError(f'{H}pressure.low_side_min = {lo!r}: expected <= '
                         f'{H}pressure.low_side_max ({hi!r})', H + 'pressure.low_side_min')


def check_corners(p: dict) -> None:
    """Each monitor's low-pass corner at most the Nyquist frequency 1/(2 plant.sim.Ts)."""
    from ..config.params import ParamError
    ts = p['plant.sim.Ts']
    for name in ('speed', 'pressure', 'estimator'):
        f = p[f'{H}{name}.lowpass']
        if f > 0.5 / ts:
            raise ParamError(f'{H}{name}.lowpass = {f!r}: expected <= the Nyquist frequency '
                             f'1/(2 plant.sim.Ts) = {0.5 / ts:g} Hz (plant.sim.Ts = {ts!r})',
                             f'{H}{name}.lowpass')


SCHEMA = PLANT_SCHEMA + Schema('switch_manager', NODE.params, _chain(check, check_corners))
