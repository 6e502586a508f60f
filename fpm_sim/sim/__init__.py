"""Headless nonlinear simulation: rollouts, the virtual impact test, the dm_control environment."""
