"""The amplification judges: the independent networks and kinematic rule that decide whether a movement encodes fear.

The judges' models live with the other encoder networks in :mod:`cogblocks.amplification.judges` (the optimised
blender constrains ensembles of the same kind); this is where evaluation finds them, together with the shipped
panel :func:`amplification_judges`.
"""

from cogblocks.amplification.judges import JUDGE_ENSEMBLE, Judges, KinematicJudge, kinematic_features, load_ensemble
from cogblocks.diagrams.amplification_setup import amplification_judges

__all__ = ["JUDGE_ENSEMBLE", "Judges", "KinematicJudge", "amplification_judges", "kinematic_features", "load_ensemble"]
