"""The shipped optimised blender's setting is OptimalBlender's own defaults, written in one place."""

import inspect

from cogblocks.amplification import OptimalBlender
from cogblocks.diagrams.amplification_setup import COMPONENTS, OPTIMISED


def test_optimised_is_the_class_defaults_and_the_subspace_size():
    defaults = {n: p.default for n, p in inspect.signature(OptimalBlender).parameters.items()}
    assert {k: v for k, v in OPTIMISED.items() if k != "components"} == {
        k: defaults[k] for k in OPTIMISED if k != "components"
    }
    assert OPTIMISED["components"] == COMPONENTS == 12
    # the validated setting, as the class docstring lists it
    assert OPTIMISED == {
        "solver": "linearised", "time_limit_ms": 4.0, "solve_ticks": 6, "iterations": 40, "realism": 3000.0,
        "margin": 0.09999, "removal_margin": 0.09999, "emit": "tail", "guard_rest": True, "neighbours": 5,
        "terminal_margin": 15.0, "components": 12,
    }  # fmt: skip
    doc = inspect.getdoc(OptimalBlender)
    assert "What ships" in doc and "0.09999" in doc and 'emit="tail"' in doc
