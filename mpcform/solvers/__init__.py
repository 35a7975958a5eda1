"""QP backends behind one interface (:mod:`.base`) and one table of names (:mod:`.registry`).

One module per backend family: :mod:`.persistent` (osqp, piqp), :mod:`.qpsolvers_backend`,
:mod:`.casadi_conic` and :mod:`.exact` (casadi + ipopt on the exact non-convex problem);
:mod:`.stored` holds what the set-up-every-call families share.
"""
