"""The cogblocks engine: typed-port blocks, hierarchical diagrams, a fixed-step multirate scheduler."""

from cogblocks.sim.block import Block
from cogblocks.sim.check import StateCheck, UndeclaredStateError, check_block
from cogblocks.sim.compiled import CompiledDiagram
from cogblocks.sim.diagram import Diagram
from cogblocks.sim.errors import DiagramError, SimulationError
from cogblocks.sim.graph import PortEnd, Wire
from cogblocks.sim.ports import Input, Output
from cogblocks.sim.signal import ANY, Signal
from cogblocks.sim.simulator import Simulator
from cogblocks.sim.timing import BASE_STEP
from cogblocks.sim.trace import Trace

__all__ = [
    "ANY",
    "BASE_STEP",
    "Block",
    "CompiledDiagram",
    "Diagram",
    "DiagramError",
    "Input",
    "Output",
    "PortEnd",
    "Signal",
    "SimulationError",
    "Simulator",
    "StateCheck",
    "Trace",
    "UndeclaredStateError",
    "Wire",
    "check_block",
]
