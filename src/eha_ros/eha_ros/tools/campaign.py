"""scripts/campaign: one scenario of config/campaigns/ over a plant family, on Dask."""
from __future__ import annotations

import argparse
import sys

from ..core.config.cli import guarded

EPILOG = """\
scenarios: config/campaigns/<name>.yaml ({names}); a path to your own YAML works too.
families:  thesis    the 270 plants of Table 4.5 (the QFT design grid)
           random:N  N plants, seeded Latin hypercube over config/campaigns/family_random.yaml
                     (beyond Table 4.5; also friction, sensor noise, leakage split)
           FILE      CSV or Parquet with columns C_eq, D_p, beta, k_T, k_E
                     [, friction, noise, leak_split] (multipliers of config/plant.yaml)
Only the plant varies; estimator, controller and switch manager keep config/'s nominal values.
--oracle gives the estimator each run's plant parameters instead (no adaptive states;
core.sim.oracle). Beside the stack's campaign with the same --seed (the same noise run by run):
a run only the stack fails was lost to learning the parameters; one both fail was not
(--compare STACK ORACLE lists the runs that pass on one side only).
--plant-params FILE centres the family on another plant: the plant.* keys of FILE (an
identified plant, scripts/identify's identified.yaml) replace config/'s before the multipliers
apply; the estimator and controller still keep config/'s values.
Output (--out, default out/campaign/<scenario>-<family>-<time>/): results.parquet (one row per
plant), campaign.json, report.md with plots, traces.npz, parts/ (rows as they finish).
Ctrl-C keeps the finished rows; --resume DIR runs the rest.
Seeds: each run draws its own noise from (--seed, its run id); random:N is drawn with --seed.
Several scenarios and/or --seeds A-B run as a set on one cluster: one campaign folder per
scenario and seed under --out, and summary.md / summary.json (passed per seed, the worst seed,
every failure). Figures of record come from the held-out seeds 101-105 (--seeds record), which
no tuning reads; tuning looks at seeds 1-5 (--seeds tuning). Rerunning a set with the same
--out keeps its finished campaigns and resumes the unfinished one.
--compare A B: did a change move anything? (e.g. the same campaign before and after a refactoring)
Two sets: campaign by campaign, and the runs passed per scenario over its seeds, lost and gained.
Scale out: on each machine install the repository (scripts/setup), then
  .venv/bin/dask scheduler                       # on one machine, port 8786
  .venv/bin/dask worker tcp://HOST:8786 --nthreads 1 --nworkers N   # on every machine
  scripts/campaign step --scheduler tcp://HOST:8786
"""


def main(argv=None) -> int:
    from ..core.sim import scenarios
    ap = argparse.ArgumentParser(
        prog='campaign', formatter_class=argparse.RawDescriptionHelpFormatter,
        description='Run one scenario of the nonlinear closed loop (plant, Kalman estimator, '
                    'QFT controller, switch manager; batch, compiled) on every plant of a '
                    'family, in parallel on Dask.',
        epilog=EPILOG.format(names=', '.join(scenarios.available())))
    ap.add_argument('scenario', nargs='*', help='scenario name(s) or YAML path(s) (none with '
                                                '--resume); several run as a set')
    ap.add_argument('--family', default='thesis', help='thesis | random:N | FILE '
                                                      '(default thesis)')
    ap.add_argument('--seed', type=int, default=None,
                    help='campaign seed: each run draws its noise from (seed, run id); also '
                         'the seed of the random family (default 1)')
    ap.add_argument('--seeds', default=None, metavar='A-B',
                    help='run the scenario(s) on each of these seeds as a set: A-B, a comma '
                         'list, "record" (the held-out 101-105) or "tuning" (1-5)')
    ap.add_argument('--workers', type=int, default=None,
                    help='LocalCluster worker processes (default: one per core)')
    ap.add_argument('--scheduler', default=None,
                    help='address of a running Dask scheduler, e.g. tcp://host:8786 '
                         '(default: start a LocalCluster)')
    ap.add_argument('--out', default=None, help='output folder (must not hold a campaign)')
    ap.add_argument('--plant-params', default=None, metavar='FILE',
                    help='the family\'s centre: plant.* keys of FILE over config/plant.yaml '
                         '(an identified plant); kept by --resume')
    ap.add_argument('--oracle', action='store_true',
                    help='the runs\' estimator is given each run\'s plant parameters instead '
                         'of learning them (no adaptive states; the same noise); kept by '
                         '--resume')
    ap.add_argument('--resume', default=None, metavar='DIR',
                    help='finish the interrupted campaign in DIR')
    ap.add_argument('--no-report', action='store_true', help='skip report.md and its plots')
    ap.add_argument('--quiet', action='store_true', help='no progress lines')
    ap.add_argument('--compare', nargs=2, metavar=('DIR_A', 'DIR_B'), default=None,
                    help='run nothing: compare two campaign folders run by run (every column '
                         'of results.parquet and every trace array, exactly), or two sets '
                         '(--seeds, several scenarios) campaign by campaign with the runs '
                         'passed per scenario, lost and gained; exit 0 when identical, 1 when '
                         'not')
    args = ap.parse_args(argv)

    def run():
        from ..core.config.cli import UsageError
        if args.compare:
            if args.scenario or args.resume:
                raise UsageError('--compare runs nothing: drop the scenario and --resume')
            from ..core.sim import compare as C
            a, b = args.compare
            set_a, set_b = C.campaigns(a), C.campaigns(b)
            if set_a or set_b:                            # sets: campaign by campaign
                if not (set_a and set_b):
                    raise UsageError(f'--compare {a} {b}: one is a set of campaigns, the '
                                     f'other not: give two campaign folders or two sets')
                result, lines = C.compare_sets(set_a, set_b), C.set_summary
            else:
                result, lines = C.compare(a, b), C.summary
            print('\n'.join(lines(result)))
            return 0 if result.identical else 1
        from ..core.sim.campaign import run_campaign
        if args.seed is not None and args.seeds is not None:
            raise UsageError('give --seed or --seeds, not both')
        if args.resume and (args.seeds or len(args.scenario) > 1):
            raise UsageError('--resume finishes one campaign; to finish a set, run the same '
                             'command with the same --out again')
        if args.workers is not None and args.workers < 1:
            raise UsageError(f'--workers {args.workers}: expected at least 1')
        if args.scheduler and args.workers:
            raise UsageError('--workers starts a LocalCluster; with --scheduler the running '
                             'cluster decides: give one of them')
        if args.resume and args.out:
            raise UsageError('--resume DIR writes into DIR: drop --out')
        if args.seeds is not None or len(args.scenario) > 1:
            return run_set(args)
        res = run_campaign(args.scenario[0] if args.scenario else None, args.family,
                           1 if args.seed is None else args.seed, args.workers, args.scheduler,
                           args.out, args.resume, progress=not args.quiet,
                           report=not args.no_report,
                           log=lambda s: print(s, file=sys.stderr, flush=True),
                           plant_params=args.plant_params, oracle=args.oracle)
        i = res.info
        print(f'campaign {i["scenario"]["name"]}: {i["rows"]} runs, {i["passed"]} passed, '
              f'{i["failed"]} failed ({i["errors"]} errors); wall {i["wall_s"]:.1f} s, first '
              f'row {i["first_row_s"]} s, {i["plant_s_per_wall_s"]:.1f} plant-s per wall-s on '
              f'{i["workers"]} worker(s)')
        if i['failed']:
            df = res.results
            bad = df[~df['passed'].astype(bool)]
            from collections import Counter
            cnt = Counter(s for f in bad['failed_specs'] for s in str(f).split(',') if s)
            print('failed specs: ' + ', '.join(f'{k} ({v})' for k, v in cnt.most_common()))
        print(f'results: {res.out_dir}/results.parquet, report: {res.out_dir}/report.md')
        return 0

    return guarded('campaign', run)


def run_set(args) -> int:
    """Several scenarios and/or seeds on one cluster (core.sim.campaign_set)."""
    from ..core.config.cli import UsageError
    from ..core.sim import campaign as C
    from ..core.sim import campaign_set as CS
    if not args.scenario:
        raise UsageError('no scenario given: name one or more')
    seeds = CS.parse_seeds(args.seeds) if args.seeds is not None else \
        [1 if args.seed is None else args.seed]
    out = args.out or C.default_out('set', args.family)
    for s in args.scenario:                           # bad names fail before the cluster
        C.SC.load(s)
    if args.plant_params:
        C.centre(args.plant_params)                   # a bad file, too
    C.FAM.resolve(args.family, seeds[0])
    client, cluster = C.connect(args.workers, args.scheduler)
    log = (lambda s: print(s, file=sys.stderr, flush=True))
    try:
        summary = CS.run_set(args.scenario, args.family, seeds, out, client, log=log,
                             progress=not args.quiet, report=not args.no_report,
                             plant_params=args.plant_params, oracle=args.oracle)
    finally:
        C.disconnect(client, cluster)
    roles = ', '.join(sorted(set(summary['roles'].values())))
    print(f'campaign set {args.family}, seeds {args.seeds or seeds[0]} ({roles}): '
          f'{summary["wall_s"]:.0f} s')
    for name, s in summary['scenarios'].items():
        per = ' '.join(f'{k}:{v["passed"]}' for k, v in s['per_seed'].items())
        print(f'  {name}: {per} of {s["runs"]}; worst seed {s["worst_seed"]} '
              f'({s["worst_passed"]}), {len(s["failures"])} failing runs in all')
    print(f'summary: {out}/summary.md')
    return 0


if __name__ == '__main__':
    sys.exit(main())
