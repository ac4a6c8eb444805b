"""Every public block class of the library, by name: what a block listing or a test sweep iterates over."""

from __future__ import annotations

import importlib
import inspect

from cogblocks.sim.block import Block

__all__ = ["PACKAGES", "package_of", "public_blocks"]

#: The packages whose ``__all__`` holds the public blocks, one per layer of the architecture: the
#: general blocks, the two Proofs of Principle and the phase and sensing blocks they share. A block's
#: documented import path is ``<package>.<class name>``.
PACKAGES = (
    "cogblocks.blocks",
    "cogblocks.sync",
    "cogblocks.amplification",
    "cogblocks.phase",
    "cogblocks.sensing",
)


def public_blocks() -> dict[str, type[Block]]:
    """Every public block class, keyed by its class name (no two public blocks share one).

    Imports torch and casadi.

    Returns
    -------
    dict of str to type
        ``{"Blender": cogblocks.sync.Blender, ...}``; ``cls.__module__`` is the module that
        defines it, :func:`package_of` the package it is imported from.

    Raises
    ------
    RuntimeError
        If two packages export different blocks under one name.
    """
    found: dict[str, type[Block]] = {}
    for package in PACKAGES:
        mod = importlib.import_module(package)
        for name in mod.__all__:
            obj = getattr(mod, name)
            if inspect.isclass(obj) and issubclass(obj, Block):
                if name in found and found[name] is not obj:
                    raise RuntimeError(f"two public blocks are named {name!r}: {found[name]} and {obj}")
                found[name] = obj
    return found


def package_of(cls: type[Block]) -> str:
    """The package a public block is documented and imported from (``"cogblocks.sync"`` for ``Blender``)."""
    for package in PACKAGES:
        mod = importlib.import_module(package)
        if cls.__name__ in mod.__all__ and getattr(mod, cls.__name__) is cls:
            return package
    raise ValueError(f"{cls.__module__}.{cls.__name__} is not a public block")
