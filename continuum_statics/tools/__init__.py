"""Command-line tools: solve, bench, demo (and record, plot, calibrate)."""
