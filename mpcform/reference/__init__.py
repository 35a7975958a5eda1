"""Desired formation trajectories xi_d(t): closed-form references and ruckig missions."""
