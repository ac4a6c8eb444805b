"""The read-only view of a diagram's graph: wire ends and wires between direct children."""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["PortEnd", "Wire"]


class PortEnd(NamedTuple):
    """One end of a wire inside a diagram: a direct child's name and one of its ports' names."""

    block: str
    port: str

    def __str__(self) -> str:
        return f"{self.block}.{self.port}"


class Wire(NamedTuple):
    """A wire between two direct children of a diagram, from an output to an input."""

    source: PortEnd
    target: PortEnd
