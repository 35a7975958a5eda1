"""The receding-horizon QP planner, problem -> QP -> solve -> first input, in rooms:

- :mod:`~mpcform.mpc.constraints`: the constraint families (velocity, acceleration, geofence,
  drone pairs, obstacles) and the braking tail they are written at, with the QP's variable layout
  and the separation items each step holds;
- :mod:`~mpcform.mpc.solve`: what solves a step's QP (the joint sparse QP with a backend, or
  each drone's dense QP with its split rounds);
- :mod:`~mpcform.mpc.safety`: certification and the safe fallback, the hard first rows under a
  velocity loop, the growth's premise in wind and the planner of the drones still flying;

and at the top the planner (:mod:`~mpcform.mpc.planner`), its settings (:mod:`~mpcform.mpc.settings`,
:mod:`~mpcform.mpc.strategy`), the plan and its rollout (:mod:`~mpcform.mpc.plan`), where a plan
takes the drones (:mod:`~mpcform.mpc.prediction`, :mod:`~mpcform.mpc.velocity_loop`), the step's
record (:mod:`~mpcform.mpc.step_info`) and the tie-break (:mod:`~mpcform.mpc.liveness`).
"""
