"""Live view cost (issue 20): the composed real-time stack without and with the live node (in
eha_loop, as run_stack --live runs it), in one run: answered ticks, latency p99, and the live
server's CPU (goal <= 10 % of a core) = the loop process's CPU with the live node and one
WebSocket client subscribed to every channel at full rate minus its CPU without the live node.
Split in two: serving the viewer (the same process without, then with the viewer: the least
noisy figure) and the node's presence without a viewer (two processes compared)."""
from __future__ import annotations

from .stack import GOALS, measure_stack

GOAL_LIVE_CPU = 0.10


def run(args) -> dict:
    duration = args.duration or 20.0
    result = {'duration_s': duration}
    for label, live in (('without_live', False), ('with_live', True)):
        print(f'bench live: composed stack {label.replace("_", " ")} for '
              f'{duration * (2 if live else 1):g} s{" (no viewer, then one)" if live else ""} '
              f'...', flush=True)
        r = measure_stack(duration, composed=True, live=live)
        result.update({f'{label}_{k}': v for k, v in r.items()})
    w, wo, loop = 'with_live_', 'without_live_', 'cpu_eha_loop_cores'
    result['live_cpu_cores'] = result[w + loop] - result[wo + loop]
    result['live_serving_cpu_cores'] = result[w + loop] - result[w + loop + '_no_viewer']
    result['live_idle_cpu_cores'] = result[w + loop + '_no_viewer'] - result[wo + loop]
    result['live_serving_us_per_message'] = 1e6 * result['live_serving_cpu_cores'] / \
        max(result[w + 'viewer_messages_per_s'], 1.0)
    result['loop_cpu_ratio_with_to_without'] = result[w + loop] / result[wo + loop]
    result['goal_answered_met'] = result[w + 'answered_fraction'] >= GOALS['answered_fraction']
    result['goal_latency_met'] = (result[w + 'latency_p99_s'] or 1.0) <= GOALS['latency_p99_s']
    result['goal_live_cpu_met'] = result['live_cpu_cores'] <= GOAL_LIVE_CPU
    return result
