"""QP backends behind one interface and one registry."""
