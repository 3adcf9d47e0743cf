"""System identification (thesis section 3.6, issue 43): experiments and fitting."""
