"""The flight export: retiming, polynomials, setpoint CSVs, Crazyswarm2 files, limits, yaw, flight check."""
