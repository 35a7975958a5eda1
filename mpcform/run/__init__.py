"""Running scenarios: the runner, sweeps and the worker pool."""
