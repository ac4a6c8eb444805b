"""cogblocks: the cognitive architectures of L1/L2 virtual humans as composable discrete-time blocks."""

from cogblocks.sim import Block, Diagram, DiagramError, Signal, Simulator, Trace

__version__ = "0.2.0"

__all__ = ["Block", "Diagram", "DiagramError", "Signal", "Simulator", "Trace", "__version__"]
