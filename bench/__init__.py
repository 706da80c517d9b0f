"""rob6 benchmarks: ``make bench`` (python -m bench) prints one table per area."""
