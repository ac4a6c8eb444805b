"""Experiments at scale: parameter sweeps on joblib or Dask, diagrams and traces as files, held-out evaluations."""
