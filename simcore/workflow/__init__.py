"""The user's workflow around a run: reports, terminal output, results on a store or a cluster."""
