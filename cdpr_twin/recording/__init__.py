"""Where a run's ticks go: timeseries.csv and the Rerun recording."""
