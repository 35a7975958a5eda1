"""What solves a step's QP (:mod:`~mpcform.mpc.solve.problem`), built by
:mod:`~mpcform.mpc.solve.factory` from the solve strategy: the joint sparse QP
(:mod:`~mpcform.mpc.solve.sparse_qp`) with a backend (:mod:`~mpcform.mpc.solve.sparse`), or in
decoupled mode each drone's condensed QP (:mod:`~mpcform.mpc.solve.condensed`,
:mod:`~mpcform.mpc.solve.per_drone`, its working sets :mod:`~mpcform.mpc.solve.working_set` and
record :mod:`~mpcform.mpc.solve.drone_solves`) with the pair rows' split rounds
(:mod:`~mpcform.mpc.solve.split`, :mod:`~mpcform.mpc.solve.sensitivity`)."""
