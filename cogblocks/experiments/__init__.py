"""Experiments at scale: parameter sweeps on joblib or Dask, diagrams and traces as files.

``from cogblocks.experiments import sweep`` gives the sweep function; its module is
:mod:`cogblocks.experiments.sweep`. Held-out evaluations are in :mod:`cogblocks.evaluation`.
"""

from cogblocks.experiments.sweep import RunSpec, SweepWarning, grid_points, save_results, sweep, sweep_seeds

__all__ = ["RunSpec", "SweepWarning", "grid_points", "save_results", "sweep", "sweep_seeds"]
