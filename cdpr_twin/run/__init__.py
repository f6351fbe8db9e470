"""A run: the control loop, its metrics, its summary, and stops (Ctrl-C, SIGTERM)."""
