"""Closed-loop simulation and metrics."""
