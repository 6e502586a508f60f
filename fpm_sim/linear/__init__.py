"""Static equilibrium, linearisation (transitionFD and constrained) and modes."""
