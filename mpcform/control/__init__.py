"""Controllers behind one stateful interface: eq. 4/7/14 laws, null space (eq. 15), consensus (eq. 20)."""
