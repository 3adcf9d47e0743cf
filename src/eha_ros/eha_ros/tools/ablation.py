"""scripts/ablation: the estimator's stages switched off one at a time over campaign sets."""
from __future__ import annotations

import argparse
import os
import sys

from ..core.config.cli import guarded

EPILOG = """\
stages (each switched off by leaving it out of estimator.stages; docs/parameters.md says what
each one adds to the Kalman filter of eq. 4.35):
{stages}
Knobs: --vary KEY=V1,V2 (repeatable) runs the scenarios with the estimator.* parameter KEY
at each value instead, e.g. --vary model.flow_share=0.5,2: a knob whose values change no
passed run and no worst figure is a candidate for removal (issue 44). With --vary alone only
the knob variants run; add --stages to run stages as well.
Runs the scenarios with every stage on (all_on), then with each stage off, on the same family
and seeds: one campaign set per stage under --out/<stage>/ (its scenarios/ folder holds the
scenario YAMLs with the overrides), then --out/ablation.md and ablation.json: per stage and
scenario the passed runs summed over the seeds and their change from all_on, each spec's worst
figure and its change, and a verdict: earns (off costs a passed run or worsens a worst figure by
more than 5 %), harmful (off only gains passed runs), no effect.
Default scenarios: {scenarios}.
Decide on the tuning seeds (--seeds tuning, 1-5); report on the held-out ones (--seeds record,
101-105). Rerunning with the same --out keeps the finished
campaigns and resumes the rest. Campaign cost: scripts/campaign's, times 1 + the stages.
"""


def main(argv=None) -> int:
    from ..core.sim import ablation as A
    ap = argparse.ArgumentParser(
        prog='ablation', formatter_class=argparse.RawDescriptionHelpFormatter,
        description='Switch the estimator\'s stages off one at a time and measure what each '
                    'one is worth over the campaigns (issue 44).',
        epilog=EPILOG.format(
            stages='\n'.join(f'  {k}' for k in A.STAGES),
            scenarios=', '.join(A.SCENARIOS)))
    ap.add_argument('scenario', nargs='*', help=f'scenario name(s) or YAML path(s) (default: '
                                                f'{", ".join(A.SCENARIOS)})')
    ap.add_argument('--stages', default=None, metavar='A,B',
                    help='comma list of the stages to switch off (default: all, none with '
                         '--vary)')
    ap.add_argument('--vary', action='append', default=[], metavar='KEY=V1,V2',
                    help='an estimator.* parameter and the values to try (repeatable)')
    ap.add_argument('--family', default='thesis', help='thesis | random:N | FILE '
                                                      '(default thesis)')
    ap.add_argument('--seeds', default='tuning', metavar='A-B',
                    help='A-B, a comma list, "tuning" (1-5, the default) or "record" '
                         '(the held-out 101-105)')
    ap.add_argument('--workers', type=int, default=None,
                    help='LocalCluster worker processes (default: one per core)')
    ap.add_argument('--scheduler', default=None,
                    help='address of a running Dask scheduler (default: start a LocalCluster)')
    ap.add_argument('--out', default=None,
                    help='output folder (default out/ablation/<family>-<time>/)')
    ap.add_argument('--quiet', action='store_true', help='no progress lines')
    args = ap.parse_args(argv)

    def run():
        from ..core.config.cli import UsageError
        from ..core.sim import campaign as C
        from ..core.sim import campaign_set as CS
        knobs = A.knob_variants(args.vary)
        stages = A.parse_stages(args.stages) if args.stages or not knobs else []
        variants = {**{s: A.STAGES[s] for s in stages}, **knobs}
        seeds = CS.parse_seeds(args.seeds)
        scenarios = args.scenario or list(A.SCENARIOS)
        for s in scenarios:                               # bad input fails before the cluster
            C.SC.load(s)
        A.check_overrides(variants)
        C.FAM.resolve(args.family, seeds[0])
        if args.workers is not None and args.workers < 1:
            raise UsageError(f'--workers {args.workers}: expected at least 1')
        if args.scheduler and args.workers:
            raise UsageError('--workers starts a LocalCluster; with --scheduler the running '
                             'cluster decides: give one of them')
        out = args.out or os.path.join(
            'out', 'ablation', os.path.basename(C.default_out('ablation', args.family)))
        client, cluster = C.connect(args.workers, args.scheduler)
        log = (lambda s: print(s, file=sys.stderr, flush=True))
        try:
            result = A.run(variants, scenarios, args.family, seeds, out, client, log=log,
                           progress=not args.quiet)
        finally:
            C.disconnect(client, cluster)
        for stage in result['rows']:
            if stage != A.BASE:
                cells = ', '.join(f'{n} {c["passed"] - c["base_passed"]:+d}'
                                  for n, c in result['rows'][stage].items())
                print(f'  {stage}: {A.verdict(result, stage)} ({cells})')
        print(f'ablation: {out}/ablation.md')
        return 0

    return guarded('ablation', run)


if __name__ == '__main__':
    sys.exit(main())
