"""Analyses that drive the simulated plant and return plain, inspectable results."""
