"""Outside the loop: recordings (MCAP), CDR, reports, the live view's protocol."""
