"""Checking a flattened diagram: every input driven, and every port's spec resolved and compatible.

Outputs declared ``like=`` an input copy that input's resolved spec (with overrides), so specs
propagate from typed blocks through generic ones; an input's spec is the merge of what it declares
and what drives it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from cogblocks.sim.errors import DiagramError
from cogblocks.sim.ports import Input
from cogblocks.sim.signal import Signal

__all__ = ["check_driven", "resolve_specs"]


def check_driven(leaves: dict[str, Any], drivers: dict, external: dict, name: Callable[[Any], str]) -> None:
    """Refuse inputs that nothing drives and that have no default."""
    fed_externally = {inp for targets in external.values() for inp in targets}
    missing = [
        name(inp)
        for block in leaves.values()
        for inp in block._inputs.values()
        if inp not in drivers and inp not in fed_externally and inp.default is None
    ]
    if missing:
        raise DiagramError(
            "unconnected input(s) with no default: "
            + ", ".join(missing)
            + "; connect them, expose them as diagram inputs, or give the port a default"
        )


def resolve_specs(
    diagram: Any,
    leaves: dict[str, Any],
    drivers: dict,
    external: dict,
    exposed_outputs: dict[str, Any],
    name: Callable[[Any], str],
) -> None:
    """Give every output copying an input (``like=``) and every input its concrete spec; refuse mismatches."""
    ext_specs = {inp: diagram.inputs[n].spec for n, targets in external.items() for inp in targets}

    def source_spec(inp: Input) -> Signal | None:
        if inp in drivers:
            return drivers[inp].spec
        if inp in ext_specs:
            spec = ext_specs[inp]
            return spec if spec.concrete else None
        default = inp.default
        return inp.declared.merge(
            Signal(shape=default.shape, dtype=np.float64 if default.dtype.kind in "iuf" else default.dtype)
        )

    pending = [o for b in leaves.values() for o in b._outputs.values() if o.like is not None]
    for out in pending:
        out.spec = None
    while pending:
        progressed = []
        for out in pending:
            spec = source_spec(out.block._inputs[out.like])
            if spec is not None:
                # an override may be a function of the copied field (an integrator's unit)
                out.spec = spec.with_(
                    **{
                        field: value(getattr(spec, field)) if callable(value) else value
                        for field, value in out.like_overrides.items()
                    }
                )
                progressed.append(out)
        if not progressed:
            _refuse_open_diagram_inputs(diagram, pending, external, name)
            names = ", ".join(name(o) for o in pending)
            raise DiagramError(
                f"cannot infer the spec of {names}: their inputs are fed only by other generic blocks "
                "(a loop); give one of them an explicit spec (shape=..., unit=...)"
            )
        pending = [o for o in pending if o not in progressed]
    for block in leaves.values():
        for inp in block._inputs.values():
            spec = source_spec(inp)
            if spec is None:
                raise DiagramError(
                    f"input {name(inp)} is fed by a diagram input whose spec is not fully known "
                    f"({inp.declared}); give expose_input(..., spec=Signal(...))"
                )
            src_name = name(drivers[inp]) if inp in drivers else "its source"
            problem = spec.mismatch(inp.declared)
            if problem:
                raise DiagramError(f"cannot connect {src_name} {spec} to {name(inp)} {inp.declared}: {problem}")
            inp.spec = inp.declared.merge(spec)
    for out_name, port in diagram.outputs.items():
        port.spec = exposed_outputs[out_name].spec


def _refuse_open_diagram_inputs(diagram: Any, pending: list, external: dict, name: Callable[[Any], str]) -> None:
    """Name the diagram inputs without a full spec that leave generic blocks with nothing to copy."""
    for input_name, targets in external.items():
        spec = diagram.inputs[input_name].spec
        fed = [name(o) for o in pending if o.block._inputs[o.like] in targets]
        if fed and not spec.concrete:
            raise DiagramError(
                f"the diagram input {input_name!r} has no full spec ({spec}) and feeds only generic blocks "
                f"({', '.join(fed)}: outputs that copy the spec of their input), so nothing tells its shape "
                "and unit; "
                f"give it one: expose_input({input_name!r}, ..., spec=Signal(shape=..., unit=...))"
            )
