"""The receding-horizon QP planner: limits, settings, rows, QP, per-drone solve, planner."""
