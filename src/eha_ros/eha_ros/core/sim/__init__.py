"""Nonlinear closed-loop simulation over plant families (DESIGN.md "three ways", 3).

family.py     the plant variants: Table 4.5 grid, Latin-hypercube boxes, files of multipliers
scenarios.py  campaign scenarios (config/campaigns/*.yaml): signals, events and figures of merit
campaign.py   one scenario over a family on Dask (scripts/campaign)
linear.py     the linear prediction of the same loop per plant (core.qft models)
report.py     report.md with envelopes, metric-vs-multiplier plots and the worst runs
"""
