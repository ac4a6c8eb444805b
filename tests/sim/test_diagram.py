"""Diagram's public view of its graph, and the explicit compile it asks for."""

from __future__ import annotations

import ast
import warnings
from pathlib import Path

import pytest

from cogblocks.blocks import Constant, Gain, Integrator, Probe
from cogblocks.sim import BASE_STEP, Diagram, PortEnd, Simulator, Wire

ROOT = Path(__file__).resolve().parents[2] / "cogblocks"

#: Diagram's own private fields: only cogblocks/sim/diagram.py reads or writes them.
PRIVATE = {"_children", "_wires", "_exposed_in", "_exposed_out", "_compiled", "_revision", "_parent", "_all_blocks"}


def private_uses(source: str) -> list[tuple[int, str]]:
    """Line and name of every use of a Diagram private field on another object than ``self``.

    Attribute access (``d._children``) and the string forms (``getattr(d, "_parent")``,
    ``d.__dict__.get("_compiled")``) both count.
    """
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and node.attr in PRIVATE:
            if not (isinstance(node.value, ast.Name) and node.value.id == "self"):
                found.append((node.lineno, node.attr))
        elif isinstance(node, ast.Constant) and node.value in PRIVATE:
            found.append((node.lineno, node.value))
    return found


def test_no_module_outside_diagram_py_touches_diagram_private_fields():
    offenders = [
        f"{path.relative_to(ROOT.parent)}:{line} uses {name}"
        for path in sorted(ROOT.rglob("*.py"))
        if path.name != "diagram.py" or path.parent.name != "sim"
        for line, name in private_uses(path.read_text())
    ]
    assert not offenders, "\n".join(offenders)


def test_the_scan_finds_every_form_of_private_use():
    source = 'd._children\nself._revision\ngetattr(b, "_parent", None)\nb.__dict__.get("_compiled")\nd.blocks\n'
    assert private_uses(source) == [(1, "_children"), (3, "_parent"), (4, "_compiled")]


def _chain() -> Diagram:
    inner = Diagram()
    inner.add("g", Gain(3.0))
    inner.expose_input("u", "g.u")
    inner.expose_output("y", "g.y")
    d = Diagram()
    d.add("c", Constant(2.0))
    d.add("inner", inner)
    d.add("x", Integrator())
    d.connect("c.y", "inner.u")
    d.connect("inner.y", "x.u")
    d.expose_output("total", "x.y")
    return d


def test_the_graph_view_lists_children_wires_and_exposed_ports():
    d = _chain()
    assert list(d.blocks) == ["c", "inner", "x"]
    assert d.wires == (
        Wire(PortEnd("c", "y"), PortEnd("inner", "u")),
        Wire(PortEnd("inner", "y"), PortEnd("x", "u")),
    )
    assert str(d.wires[0].source) == "c.y"
    inner = d["inner"]
    assert dict(inner.exposed_inputs) == {"u": (PortEnd("g", "u"),)}
    assert dict(inner.exposed_outputs) == {"y": PortEnd("g", "y")}
    assert dict(d.exposed_outputs) == {"total": PortEnd("x", "y")}
    assert [type(b).__name__ for b in d.walk()] == ["Constant", "Diagram", "Gain", "Integrator"]
    assert inner.parent is d and d["inner.g"].parent is inner and d.parent is None


def test_the_graph_view_is_read_only():
    d = _chain()
    d.blocks["extra"] = Constant(1.0)
    assert "extra" not in d
    with pytest.raises(TypeError):
        d.exposed_outputs["other"] = PortEnd("c", "y")  # type: ignore[index]
    with pytest.raises(AttributeError):
        d.wires.append(None)  # type: ignore[attr-defined]
    before = d.revision
    d.add("p", Probe())
    assert d.revision > before and d["inner"].revision < d.revision


def test_step_without_compile_warns_naming_compile_then_runs_at_the_base_step():
    d = _chain()
    assert d.plan is None
    with pytest.warns(DeprecationWarning, match=r"Diagram\.step\(\).*call diagram\.compile\(dt\) first"):
        out = d.step()
    assert d.plan is not None and d.plan.dt == BASE_STEP
    assert float(out["total"]) == 0.0  # the integrator's first output is its initial state
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # compiled: no warning any more
        assert float(d.step()["total"]) == pytest.approx(6.0 * BASE_STEP)


@pytest.mark.parametrize("call", ["state_dict", "compiled"])
def test_state_dict_and_compiled_without_compile_warn(call):
    d = _chain()
    with pytest.warns(DeprecationWarning, match=call):
        getattr(type(d), call).fget(d) if call == "compiled" else d.state_dict()


def test_an_explicit_compile_gives_no_warning_and_a_change_drops_the_plan():
    d = _chain()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plan = d.compile(0.02)
        assert d.plan is plan and d.compiled is plan
        d.step()
        assert d.state_dict()["k"] == 1
        Simulator(d).run(n_steps=3)
    d.add("p", Probe())
    assert d.plan is None


def test_repr_names_blocks_and_exposed_ports():
    assert repr(_chain()) == (
        "<Diagram blocks=[c: Constant, inner: Diagram (1 blocks), x: Integrator] inputs=() outputs=(total <- x.y)>"
    )
