"""Safe state on a position-sensor fault (issue 15): who commands what, written once.

Cue: the estimator's consistency verdict ``sensor_fault`` (``PositionEstimate.consistency``,
core.estimator.adapt.monitor): the sensor is stuck (10 identical readings), or it jumped (a
one-sample innovation step with quiet pressures) and the measurement stays away from the
estimate beyond the sensor's own band for adapt.MK_N samples. A 1 mm offset: within 25 ms;
a stuck sensor: 10 ms (campaigns sensor_fault, sensor_stuck).

``filter_sensor_disagree`` alone is an alarm, not this safe state: one ERROR line, ERROR on
/diagnostics, and the estimator's own reaction -- its position process noise opens, so the
estimate falls back on the measurement and the loop goes on closed on the sensor
(adapt.disagree_noise). Without a second position sensor the disagreement does not tell a
slowly wrong sensor from a plant beyond the model, and locking a plant beyond the model can
be the worse choice: with leakage x40 under 5 kN a sealed cylinder creeps to the end stop in
2 s, while the loop on the sensor holds it within 0.5 mm (tests/test_estimator_robust.py).

- Switch manager (owns the valves): enters FAILED_SAFE in its ``switch.safe_mode`` on the
  first such estimate -- hold (default): both drives disabled, every pump valve closed, the
  chambers sealed = hydraulic lock; the piston holds its position (it creeps only by the
  cross-piston leakage). Latched like any FAILED_SAFE: only a commanded switch
  (``/eha/switch_channel``) to a healthy couple leaves it. Logged once (its event log,
  WARN), ERROR on /diagnostics.
- Controller (owns the speed command): zero motor speed with its state frozen while the cue
  holds or the manager reports FAILED_SAFE (drives off: a running integrator would only wind
  up), then a bumpless restart from the estimate (``PositionController.start``). Logged once
  per entry, ERROR on /diagnostics while it lasts.
- The plant (or bridge) applies the manager's channel select at the next tick: the lock is
  in place one tick after the estimate that carries the cue.

The controller's zero speed alone (no manager on the graph) is not a lock: a back-driven
pump lets the load move the piston. The stack's safe state needs both.
"""
from __future__ import annotations

from ..estimator import adapt
from ..redundancy.state_machine import FAILED_SAFE


def position_fault(verdict: int) -> bool:
    """The estimate's consistency verdict calls for the safe state (sensor_fault)."""
    return adapt.safe_state(int(verdict))


def controller_holds(verdict: int, manager_state: str | None) -> bool:
    """Controller at zero speed, its state frozen (see the module docstring)."""
    return position_fault(verdict) or manager_state == FAILED_SAFE


def manager_reason(verdict: int) -> str:
    return (f'position fault: estimator reports {adapt.VERDICTS[int(verdict)]} (position '
            f'sensor stuck, or offset beyond the sensor band)')
