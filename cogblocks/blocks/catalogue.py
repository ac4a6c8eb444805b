"""Every public block class of the library, by name: what a block listing or a test sweep iterates over."""

from __future__ import annotations

import importlib
import inspect

from cogblocks.sim import Block

__all__ = ["PUBLIC_MODULES", "public_blocks"]

#: Modules whose ``__all__`` holds public blocks besides ``cogblocks.blocks`` itself: the
#: Amplification blocks (the encoding ``PositionComputer`` is not re-exported), the L2
#: architectures as blocks and the optimisation-based blender.
PUBLIC_MODULES = (
    "cogblocks.blocks.encoding",
    "cogblocks.blocks.buffer",
    "cogblocks.blocks.rl",
    "cogblocks.diagrams.sync",
    "cogblocks.diagrams.amplification",
    "cogblocks.analysis.optimal_blending",
)


def public_blocks() -> dict[str, type[Block]]:
    """Every public block class, keyed by the name a user imports it by.

    Blocks of ``cogblocks.blocks`` are keyed by their class name; the others by
    ``"<module>.<class>"`` (``"encoding.PositionComputer"``, ``"sync.L2Sync"``). Imports torch
    and casadi.

    Returns
    -------
    dict of str to type
    """
    import cogblocks.blocks as package

    found: dict[str, type[Block]] = {}
    for name in package.__all__:
        obj = getattr(package, name)
        if inspect.isclass(obj) and issubclass(obj, Block):
            found[name] = obj
    for module in PUBLIC_MODULES:
        mod = importlib.import_module(module)
        for name in mod.__all__:
            obj = getattr(mod, name)
            if inspect.isclass(obj) and issubclass(obj, Block) and obj not in found.values():
                found[f"{module.rsplit('.', 1)[-1]}.{name}"] = obj
    return found
