"""Position control at Ts: discretised QFT controller and prefilter, reference handling, watchdog."""
