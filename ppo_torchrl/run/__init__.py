"""A run's lifecycle: its dir and who owns it, checkpoints, the loggers, its start line,
signals, and the background evaluations."""
