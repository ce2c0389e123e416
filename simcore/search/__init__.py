"""Adaptive search over a scenario's parameter space (`spec.search`): rounds of runs chosen by optuna."""
