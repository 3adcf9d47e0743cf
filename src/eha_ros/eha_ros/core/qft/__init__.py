"""QFT design toolchain of thesis section 4.3: plant family (Table 4.5), templates, bounds
(eqs. 4.51-4.63), PSO loop shaping (Table 4.8, eqs. 4.65-4.75), prefilter (4.77), verification
and reports. Pure numpy/scipy; frequency responses always from state space, never ss2tf."""
