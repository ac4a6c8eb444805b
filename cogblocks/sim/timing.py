"""The engine's base step: the tick every ready diagram, data set and model of the package runs at."""

__all__ = ["BASE_STEP"]

#: Seconds between two base ticks (100 Hz): the deliverable's motion capture and model rate.
BASE_STEP: float = 0.01
