"""System identification from bench recordings (thesis sec. 3.6, issue 43).

experiments.py  the four experiments' plans and their limit checks (drive, friction, leakage,
                validation); params.py, run.py: the experiment node's parameters and core
dataset.py      recordings (MCAP) to arrays on the tick grid, with the user-mistake checks
fit.py          least squares with cluster-robust intervals and the identified verdict
drive.py        velocity PI gains, delay and k_T from the speed-reference sweep (Fig. 3.36)
friction.py     eq. 3.33 from the pressure force against the piston velocity (Fig. 3.42)
leakage.py      the loaded leakage and C_eq from held loads (Fig. 3.44)
validate.py     the nominal and the identified model against the validation run (Fig. 3.45)
report.py       report.md and its figures
pipeline.py     fit_recordings: all of it, writing identified.yaml, identification.json, report.md
"""
