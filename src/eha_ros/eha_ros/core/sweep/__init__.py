"""Sweep test: reference signals (TwinCAT Fr_Test semantics, chirp, step) and FFT analysis."""
