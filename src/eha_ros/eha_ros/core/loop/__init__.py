"""The 1 kHz loop as a whole: statistics, supervisor, safe state."""
