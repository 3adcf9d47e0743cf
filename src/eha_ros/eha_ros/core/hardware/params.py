"""Parameters of the plant-side loop (nodes.plant_side), one set per executable's prefix
(plant_sim: ``sim_node``, hardware_bridge: ``bridge``); only the defaults differ."""
from __future__ import annotations

from ..config.params import Param

AUTOSTART = ('unconfigured', 'inactive', 'active')


def loop_params(prefix: str, *, command_timeout: float, autostart: str,
                max_speed_rate: float, arm_max_command: float,
                startup_discovery: float | None = None) -> list:
    """The loop's switches: lock-step (publishes /clock, steps per command, the start gate
    holds tick 0), the lifecycle at start-up, and the command gate (core.hardware.gate; the
    saturation is plant.drive.omega_max). ``startup_discovery`` only for an exclusive plant
    side (nodes.plant_side.Program.exclusive: a real drive)."""
    exclusive = [] if startup_discovery is None else [
        Param(f'{prefix}.startup_discovery', 'float', 's', startup_discovery, 0.0, 30.0,
              doc='wait this long for other eha/state publishers before refusing to start')]
    return exclusive + [
        Param(f'{prefix}.lockstep', 'bool', '', False,
              doc='step only when the command of the previous state arrived; publish /clock'),
        Param(f'{prefix}.lockstep_from_activation', 'bool', '', True,
              doc='lock-step: state(0) waits for the first activation, so a run is the same '
                  'from tick 0 (false: steps from configure, commands applied once activated)'),
        Param(f'{prefix}.lockstep_timeout', 'float', 's', 1.0, 1e-3, 60.0,
              doc='lock-step: re-publish state(k) after this wall time without command(k)'),
        Param(f'{prefix}.start_after', 'str[]', '', [''], min_len=1,
              doc='hold tick 0 (real time: the loop\'s start) until these nodes subscribe to '
                  'every /eha topic with a publisher and report each publisher matched (their '
                  '~/matched; run_stack --record adds the recorder); lock-step: no tick while '
                  'one of them is too far behind (its ~/received, nodes.common.Pace); empty '
                  'string = none'),
        Param(f'{prefix}.start_timeout', 'float', 's', 30.0, 0.0, 600.0,
              doc='start anyway (with a warning) after this wall time at tick 0'),
        Param(f'{prefix}.autostart', 'str', '', autostart, choices=AUTOSTART,
              doc='lifecycle state to reach by itself at start-up: unconfigured (wait for a '
                  'manager, e.g. run_stack), inactive (configured: states, no commands '
                  'applied) or active (commands applied once activation is allowed)'),
        Param(f'{prefix}.command_timeout', 'float', 's', command_timeout, 1e-3, 10.0,
              doc='no command for this long: zero speed applied, reported'),
        Param(f'{prefix}.max_speed_rate', 'float', 'rad/s^2', max_speed_rate, 10.0, 1.0e9,
              doc='rate limit of the applied speed reference while armed (plant_sim 1e9: '
                  'none, the drive model ramps; hardware_bridge 5e5: the 5 mm step\'s largest '
                  'jump is 4.75e5)'),
        Param(f'{prefix}.arm_max_command', 'float', 'rad/s', arm_max_command, 0.0, 1.0e5,
              doc='activation (arming) is refused while |latest command| exceeds this '
                  '(plant_sim 1e5: none)'),
        Param(f'{prefix}.diagnostics_period', 'float', 's', 1.0, 0.05, 60.0,
              doc='/diagnostics period'),
        Param(f'{prefix}.thread_priority', 'int', '', 50, 0, 99,
              doc='real time: SCHED_FIFO priority of the loop thread (ros2_control\'s '
                  'thread_priority), so other work on the machine cannot delay a tick; 0 = '
                  'normal scheduling; refused by the OS (no CAP_SYS_NICE or ulimit -r): '
                  'warned once, normal scheduling'),
    ]
