"""The receding-horizon QP planner: limits and settings; the plan and its rollout (plan); row
families (rows) and separation rows about the guess (separation); candidate items (candidates);
the tie-break (liveness); the sparse QP (qp) and what solves a step (problem, sparse, per_drone);
certification and fallback (certify); the planner that runs them (planner)."""
