"""Parameters, the node registry and the command-line guard: what a user hands the stack."""
