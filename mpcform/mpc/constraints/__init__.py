"""The planner's constraint families, one unit each, and what they share: the QP's variables and
structural rows (:mod:`~mpcform.mpc.constraints.rows`), the limit families
(:mod:`~mpcform.mpc.constraints.limits`), the separation items within reach
(:mod:`~mpcform.mpc.constraints.candidates`), the pair and obstacle units
(:mod:`~mpcform.mpc.constraints.units`) combined in :mod:`~mpcform.mpc.constraints.separation`,
and the braking tail past the horizon (:mod:`~mpcform.mpc.constraints.braking`,
:mod:`~mpcform.mpc.constraints.tail`)."""
