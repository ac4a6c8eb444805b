"""Evaluation has one place, cogblocks.evaluation; the old import paths forward to it with a DeprecationWarning."""

import importlib
import sys

import pytest

import cogblocks.evaluation as evaluation

MOVED = [
    ("cogblocks.analysis.sync_bound", "cogblocks.evaluation.sync_bound", "upper_bound"),
    ("cogblocks.experiments.sync_heldout", "cogblocks.evaluation.sync_heldout", "heldout_table"),
    ("cogblocks.phase.evaluation1d", "cogblocks.evaluation.phase1d", "evaluate_grid"),
]


@pytest.mark.parametrize(("old", "new", "name"), MOVED)
def test_an_old_path_gives_the_same_object_and_names_the_new_path(old, new, name):
    with pytest.warns(DeprecationWarning, match=rf"{old} moved to {new}; import {name} from there"):
        got = getattr(importlib.import_module(old), name)
    assert got is getattr(importlib.import_module(new), name)
    with pytest.raises(AttributeError, match="has no attribute 'nope'"):
        importlib.import_module(old).nope  # noqa: B018


def test_the_package_lists_what_users_call_and_loads_it_on_first_use():
    from cogblocks.amplification.judges import Judges
    from cogblocks.evaluation.sync_bound import upper_bound

    assert evaluation.upper_bound is upper_bound and evaluation.Judges is Judges
    assert {"heldout_table", "upper_bound", "Judges", "amplification_judges", "evaluate_grid"} <= set(
        evaluation.__all__
    )
    with pytest.raises(AttributeError, match="cogblocks.evaluation' has no attribute 'nope'"):
        evaluation.nope  # noqa: B018


def test_from_experiments_import_sweep_gives_the_function():
    from cogblocks.experiments import sweep

    assert callable(sweep) and sweep is sys.modules["cogblocks.experiments.sweep"].sweep
