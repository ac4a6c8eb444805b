"""Set-up shared by the optimised blender's tests: its options, a recorder of its predictions and random box-QP duals.

Imported as ``tests.amplification.optimal_helpers``: pytest's importlib mode registers ``tests.amplification`` when it
imports a test module of this folder.
"""

import numpy as np

from cogblocks.amplification import OptimalBlender
from cogblocks.diagrams.amplification_setup import OPTIMISED
from studies.amplification_gap import RecordingBlender


def options(**extra):
    """:data:`OPTIMISED` with a budget no solve reaches: the plans depend on the iteration limit only.

    Parameters
    ----------
    **extra
        Options added to, or replacing, these.

    Returns
    -------
    dict
        Options of :class:`~cogblocks.amplification.OptimalBlender`, as its keyword arguments.
    """
    settings = {k: v for k, v in OPTIMISED.items() if k != "components"}
    return {**settings, "time_limit_ms": 1000.0, **extra}


def eta_i_options(**extra):
    """:func:`options` with the prediction η_i and the ninth round's terminal margin (``neighbours=1``, 5 mm), which
    the tests using it rebuild from the trace; the shipped prediction is tested in ``test_optimal_neighbours.py``.

    Parameters
    ----------
    **extra
        Options added to, or replacing, these.

    Returns
    -------
    dict
        Options of :class:`~cogblocks.amplification.OptimalBlender`, as its keyword arguments.
    """
    return options(**{"neighbours": 1, "terminal_margin": 5.0, **extra})


def random_dual(rng, sizes, extra_columns, finite):
    """A random definite dual of :func:`~cogblocks.amplification.linearised.box_qp`: ``m = g gᵀ``, ``b`` and the
    upper bounds, each finite (in [0, 2)) with probability ``finite``, else infinite.

    Parameters
    ----------
    rng : numpy.random.Generator
        Drawn from, in this order: the size, the columns beyond it, ``g``, ``b``, which bounds are finite, their values.
    sizes : tuple of int
        The ``rng.integers`` range of the number of variables ``r``.
    extra_columns : tuple of int
        The ``rng.integers`` range of the columns of ``g`` beyond ``r``.
    finite : float
        The probability of a finite upper bound.

    Returns
    -------
    m : numpy.ndarray
        The ``(r, r)`` matrix.
    b : numpy.ndarray
        The ``(r,)`` linear term.
    upper : numpy.ndarray
        The ``(r,)`` upper bounds.
    """
    r = int(rng.integers(*sizes))
    g = rng.normal(size=(r, r + int(rng.integers(*extra_columns))))
    m, b = g @ g.T, rng.normal(size=r) * 3.0
    upper = np.where(rng.random(r) < finite, rng.random(r) * 2.0, np.inf)
    return m, b, upper


class PredictionRecorder(RecordingBlender):
    """A :class:`~studies.amplification_gap.RecordingBlender` that also keeps, in ``predictions``, every
    decision's tick and the prediction its problem and check were made on."""

    def reset(self) -> None:
        super().reset()
        self.predictions = []

    def _finish(self, t, new):
        self.predictions.append((self._job["t"], self._job["predicted"].copy()))
        return super()._finish(t, new)


#: The casadi setting the solver tests exercise, where they leave an option out: the SQP solver, one tick and 10
#: iterations per decision, ``v_h + u`` emitted, η_i predicted. :class:`~cogblocks.amplification.OptimalBlender`'s
#: own defaults are the shipped setting (:data:`~cogblocks.diagrams.amplification_setup.OPTIMISED`).
PLAIN = {
    "solver": "sqpmethod",
    "time_limit_ms": 8.0,
    "solve_ticks": 1,
    "iterations": 10,
    "realism": 30.0,
    "margin": 0.05,
    "removal_margin": None,
    "emit": "human",
    "guard_rest": False,
    "neighbours": 1,
    "terminal_margin": 5.0,
}


def plain_blender(*args, **kwargs):
    """An :class:`~cogblocks.amplification.OptimalBlender` with :data:`PLAIN` for the options not given."""
    return OptimalBlender(*args, **{**PLAIN, **kwargs})
