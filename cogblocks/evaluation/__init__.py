"""Evaluation users call: held-out sync groups, the sync bound, the amplification judges, the 1D phase grid.

* :mod:`cogblocks.evaluation.sync_heldout`: every motion computer on random groups of a split, against the bound;
* :mod:`cogblocks.evaluation.sync_bound`: an upper bound on the order-parameter gain any alteration reaches;
* :mod:`cogblocks.evaluation.judges`: the independent judges that decide whether a movement encodes fear;
* :mod:`cogblocks.evaluation.phase1d`: the 1D phase estimator over sensor rates, units, quantisation and noise.

Names load on first use, so importing the package costs nothing.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "evaluate_group": "cogblocks.evaluation.sync_heldout",
    "heldout_table": "cogblocks.evaluation.sync_heldout",
    "plot_heldout": "cogblocks.evaluation.sync_heldout",
    "constant_frequency_bound": "cogblocks.evaluation.sync_bound",
    "constant_frequency_scan": "cogblocks.evaluation.sync_bound",
    "upper_bound": "cogblocks.evaluation.sync_bound",
    "Judges": "cogblocks.evaluation.judges",
    "KinematicJudge": "cogblocks.evaluation.judges",
    "amplification_judges": "cogblocks.evaluation.judges",
    "evaluate_grid": "cogblocks.evaluation.phase1d",
    "evaluate_signal": "cogblocks.evaluation.phase1d",
    "plot_grid": "cogblocks.evaluation.phase1d",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'cogblocks.evaluation' has no attribute {name!r}")
