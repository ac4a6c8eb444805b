"""Errors raised by the engine."""


class DiagramError(ValueError):
    """A diagram is wired or declared wrongly.

    Raised when the diagram is built or compiled, never in the middle of a run:
    mismatched port specs, unconnected inputs, doubly driven inputs, algebraic
    loops, bad block periods.
    """


class SimulationError(RuntimeError):
    """A compiled diagram failed while running (a block broke its contract)."""
