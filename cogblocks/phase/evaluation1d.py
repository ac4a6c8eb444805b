"""Moved to :mod:`cogblocks.evaluation.phase1d`: this old path works for one release, with a DeprecationWarning."""

from cogblocks.sim.moved import forwarding

__getattr__ = forwarding(__name__, "cogblocks.evaluation.phase1d")
