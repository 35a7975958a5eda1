"""What keeps a step's command safe whatever the solve did: certification and the fallback
(:mod:`~mpcform.mpc.safety.certify`), hard first rows under a velocity loop
(:mod:`~mpcform.mpc.safety.first_rows`), the growth's premise in wind
(:mod:`~mpcform.mpc.safety.premise`) and the planner of the drones still flying
(:mod:`~mpcform.mpc.safety.survivors`)."""
