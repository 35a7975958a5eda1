"""Online planning: the planner stepped on measured positions within a deadline, returning the
full-state setpoints a Crazyflie flies (:mod:`mpcform.online.loop`)."""
