"""Text renderings of a diagram: Mermaid and Graphviz DOT."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cogblocks.sim.diagram import Diagram

__all__ = ["to_mermaid", "to_dot"]


def _node_id(path: str) -> str:
    return path.replace(".", "__")


def _leaf_label(block, name: str) -> str:
    label = f"{name}: {type(block).__name__}"
    if block.period is not None:
        label += f" every {block.period:g}s"
    return label


def _wire_ends(d: Diagram, prefix: str, child: str, port: str, inbound: bool) -> str:
    """Node id of a wire end; sub-diagram ends point at the sub-diagram's boundary node."""

    block = d._children[child]
    if block.composite:
        side = "in" if inbound else "out"
        return _node_id(f"{prefix}{child}.{side}_{port}")
    return _node_id(prefix + child)


def to_mermaid(d: Diagram) -> str:
    """Render ``d`` as a Mermaid ``flowchart LR``; sub-diagrams become subgraphs."""
    lines = ["flowchart LR"]
    _mermaid_body(d, "", lines, "    ")
    return "\n".join(lines)


def _mermaid_body(d: Diagram, prefix: str, lines: list[str], indent: str) -> None:

    for name in d._exposed_in:
        lines.append(f'{indent}{_node_id(prefix + "in_" + name)}(["{name}"])')
    for name in d._exposed_out:
        lines.append(f'{indent}{_node_id(prefix + "out_" + name)}(["{name}"])')
    for name, block in d._children.items():
        if block.composite:
            sub = prefix + name + "."
            lines.append(f'{indent}subgraph {_node_id(prefix + name)}["{name}: {type(block).__name__}"]')
            _mermaid_body(block, sub, lines, indent + "    ")
            lines.append(f"{indent}end")
        else:
            lines.append(f'{indent}{_node_id(prefix + name)}["{_leaf_label(block, name)}"]')
    for s_child, s_port, d_child, d_port in d._wires:
        src = _wire_ends(d, prefix, s_child, s_port, inbound=False)
        dst = _wire_ends(d, prefix, d_child, d_port, inbound=True)
        lines.append(f"{indent}{src} -->|{s_port} → {d_port}| {dst}")
    for name, targets in d._exposed_in.items():
        for child, port in targets:
            lines.append(
                f"{indent}{_node_id(prefix + 'in_' + name)} -->|{port}| {_wire_ends(d, prefix, child, port, True)}"
            )
    for name, (child, port) in d._exposed_out.items():
        lines.append(
            f"{indent}{_wire_ends(d, prefix, child, port, False)} -->|{port}| {_node_id(prefix + 'out_' + name)}"
        )


def to_dot(d: Diagram) -> str:
    """Render ``d`` in Graphviz DOT; sub-diagrams become clusters."""
    lines = ["digraph cogblocks {", "    rankdir=LR;", "    node [shape=box];"]
    _dot_body(d, "", lines, "    ")
    lines.append("}")
    return "\n".join(lines)


def _dot_body(d: Diagram, prefix: str, lines: list[str], indent: str) -> None:

    for name in d._exposed_in:
        lines.append(f'{indent}{_node_id(prefix + "in_" + name)} [label="{name}", shape=ellipse];')
    for name in d._exposed_out:
        lines.append(f'{indent}{_node_id(prefix + "out_" + name)} [label="{name}", shape=ellipse];')
    for name, block in d._children.items():
        if block.composite:
            lines.append(f"{indent}subgraph cluster_{_node_id(prefix + name)} {{")
            lines.append(f'{indent}    label="{name}: {type(block).__name__}";')
            _dot_body(block, prefix + name + ".", lines, indent + "    ")
            lines.append(f"{indent}}}")
        else:
            lines.append(f'{indent}{_node_id(prefix + name)} [label="{_leaf_label(block, name)}"];')
    for s_child, s_port, d_child, d_port in d._wires:
        src = _wire_ends(d, prefix, s_child, s_port, inbound=False)
        dst = _wire_ends(d, prefix, d_child, d_port, inbound=True)
        lines.append(f'{indent}{src} -> {dst} [label="{s_port} → {d_port}"];')
    for name, targets in d._exposed_in.items():
        for child, port in targets:
            dst = _wire_ends(d, prefix, child, port, True)
            lines.append(f'{indent}{_node_id(prefix + "in_" + name)} -> {dst} [label="{port}"];')
    for name, (child, port) in d._exposed_out.items():
        src = _wire_ends(d, prefix, child, port, False)
        lines.append(f'{indent}{src} -> {_node_id(prefix + "out_" + name)} [label="{port}"];')
