"""The world the drones fly in: the limits they keep (:mod:`mpcform.world.limits`), the static
obstacles with their resolved clearances (:mod:`mpcform.world.obstacles`), both together
(:mod:`mpcform.world.world`) and the description of a drone's velocity loop
(:mod:`mpcform.world.loop_groups`).

This layer sits below both the planner (:mod:`mpcform.mpc`) and the simulators
(:mod:`mpcform.sim`), which share it and do not import each other.
"""
