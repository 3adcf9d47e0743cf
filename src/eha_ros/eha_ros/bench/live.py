"""Live view cost (issue 20): the composed real-time stack without and with the live node and
one WebSocket client subscribed to every channel at full rate, in one run: answered ticks,
latency p99, CPU of the live process (goal <= 10 % of a core) and of the loop."""
from __future__ import annotations

from .stack import GOALS, measure_stack

GOAL_LIVE_CPU = 0.10


def run(args) -> dict:
    duration = args.duration or 20.0
    result = {'duration_s': duration}
    for label, live in (('without_live', False), ('with_live', True)):
        print(f'bench live: composed stack {label.replace("_", " ")} for {duration:g} s ...',
              flush=True)
        r = measure_stack(duration, composed=True, live=live)
        result.update({f'{label}_{k}': v for k, v in r.items()})
    w = 'with_live_'
    result['live_cpu_cores'] = result[w + 'cpu_live_cores']
    result['loop_cpu_ratio_with_to_without'] = (result[w + 'cpu_eha_loop_cores'] /
                                                result['without_live_cpu_eha_loop_cores'])
    result['goal_answered_met'] = result[w + 'answered_fraction'] >= GOALS['answered_fraction']
    result['goal_latency_met'] = (result[w + 'latency_p99_s'] or 1.0) <= GOALS['latency_p99_s']
    result['goal_live_cpu_met'] = result['live_cpu_cores'] <= GOAL_LIVE_CPU
    return result
