"""Nonlinear closed-loop simulation over plant families (DESIGN.md "three ways", 3).

batch.py      the stack in one process: BatchLoop (state(k) -> estimate(k) -> command(k)),
              BatchStack, the parameters of a node from its files in config/
closed_loop.py  the compiled segment of BatchLoop: ticks without events in one call
switchover.py the Table 3.4 switch-over runs with the switch manager, and their figures
pid_loop.py   the thesis' Table 3.8 PID in BatchLoop: around the plant, on the estimate
compare.py    two campaign folders compared run by run (scripts/campaign --compare)
family.py     the plant variants: Table 4.5 grid, Latin-hypercube boxes, files of multipliers
scenarios.py  campaign scenarios (config/campaigns/*.yaml): signals, events and figures of merit
campaign.py   one scenario over a family on Dask (scripts/campaign)
linear.py     the linear prediction of the same loop per plant (core.qft models)
report.py     report.md with envelopes, metric-vs-multiplier plots and the worst runs
"""
