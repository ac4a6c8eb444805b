"""Renderings of a diagram: Mermaid and Graphviz DOT text, and pictures drawn by Graphviz."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cogblocks.sim.diagram import Diagram

__all__ = ["draw", "to_dot", "to_mermaid"]

_TEXT_SUFFIXES = {".dot": "dot", ".gv": "dot", ".mmd": "mermaid"}
_PICTURE_SUFFIXES = (".svg", ".png", ".pdf")


def draw(d: Diagram, path: str | os.PathLike) -> None:
    """Draw ``d`` to ``path``, in the format its suffix names.

    ``.dot``/``.gv`` and ``.mmd`` are written as Graphviz and Mermaid text;
    ``.svg``, ``.png`` and ``.pdf`` are rendered by Graphviz's ``dot`` program.

    Raises
    ------
    ValueError
        For another suffix.
    RuntimeError
        For a picture when ``dot`` is not installed.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in _TEXT_SUFFIXES:
        text = to_dot(d) if _TEXT_SUFFIXES[suffix] == "dot" else to_mermaid(d)
        path.write_text(text + "\n", encoding="utf-8")
        return
    if suffix not in _PICTURE_SUFFIXES:
        known = ", ".join([*_TEXT_SUFFIXES, *_PICTURE_SUFFIXES])
        raise ValueError(f"cannot draw to {str(path)!r}: unknown suffix {suffix!r}; use one of {known}")
    dot = shutil.which("dot")
    if dot is None:
        raise RuntimeError(
            f"drawing {path.name} needs Graphviz's 'dot' program, which is not installed (e.g. apt install "
            "graphviz, or conda install graphviz); without it, draw to a .dot or .mmd file, which is plain text"
        )
    done = subprocess.run(
        [dot, f"-T{suffix[1:]}", "-o", str(path)], input=to_dot(d).encode(), capture_output=True, check=False
    )
    if done.returncode != 0:
        raise RuntimeError(f"Graphviz dot failed to draw {path.name}: {done.stderr.decode(errors='replace').strip()}")


def _node_id(path: str) -> str:
    return path.replace(".", "__")


def _leaf_label(block, name: str) -> str:
    label = f"{name}: {type(block).__name__}"
    if block.period is not None:
        label += f" every {block.period:g}s"
    return label


def _wire_ends(d: Diagram, prefix: str, child: str, port: str, inbound: bool) -> str:
    """Node id of a wire end; sub-diagram ends point at the sub-diagram's boundary node."""

    block = d.blocks[child]
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

    for name in d.exposed_inputs:
        lines.append(f'{indent}{_node_id(prefix + "in_" + name)}(["{name}"])')
    for name in d.exposed_outputs:
        lines.append(f'{indent}{_node_id(prefix + "out_" + name)}(["{name}"])')
    for name, block in d.blocks.items():
        if block.composite:
            sub = prefix + name + "."
            lines.append(f'{indent}subgraph {_node_id(prefix + name)}["{name}: {type(block).__name__}"]')
            _mermaid_body(block, sub, lines, indent + "    ")
            lines.append(f"{indent}end")
        else:
            lines.append(f'{indent}{_node_id(prefix + name)}["{_leaf_label(block, name)}"]')
    for (s_child, s_port), (d_child, d_port) in d.wires:
        src = _wire_ends(d, prefix, s_child, s_port, inbound=False)
        dst = _wire_ends(d, prefix, d_child, d_port, inbound=True)
        lines.append(f"{indent}{src} -->|{s_port} → {d_port}| {dst}")
    for name, targets in d.exposed_inputs.items():
        for child, port in targets:
            lines.append(
                f"{indent}{_node_id(prefix + 'in_' + name)} -->|{port}| {_wire_ends(d, prefix, child, port, True)}"
            )
    for name, (child, port) in d.exposed_outputs.items():
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

    for name in d.exposed_inputs:
        lines.append(f'{indent}{_node_id(prefix + "in_" + name)} [label="{name}", shape=ellipse];')
    for name in d.exposed_outputs:
        lines.append(f'{indent}{_node_id(prefix + "out_" + name)} [label="{name}", shape=ellipse];')
    for name, block in d.blocks.items():
        if block.composite:
            lines.append(f"{indent}subgraph cluster_{_node_id(prefix + name)} {{")
            lines.append(f'{indent}    label="{name}: {type(block).__name__}";')
            _dot_body(block, prefix + name + ".", lines, indent + "    ")
            lines.append(f"{indent}}}")
        else:
            lines.append(f'{indent}{_node_id(prefix + name)} [label="{_leaf_label(block, name)}"];')
    for (s_child, s_port), (d_child, d_port) in d.wires:
        src = _wire_ends(d, prefix, s_child, s_port, inbound=False)
        dst = _wire_ends(d, prefix, d_child, d_port, inbound=True)
        lines.append(f'{indent}{src} -> {dst} [label="{s_port} → {d_port}"];')
    for name, targets in d.exposed_inputs.items():
        for child, port in targets:
            dst = _wire_ends(d, prefix, child, port, True)
            lines.append(f'{indent}{_node_id(prefix + "in_" + name)} -> {dst} [label="{port}"];')
    for name, (child, port) in d.exposed_outputs.items():
        src = _wire_ends(d, prefix, child, port, False)
        lines.append(f'{indent}{src} -> {_node_id(prefix + "out_" + name)} [label="{port}"];')


def summary(d: Diagram, shown: int = 12) -> str:
    """One line naming the diagram's first ``shown`` blocks (then "… n more") and its exposed ports."""
    children = list(d.blocks.items())
    blocks = ", ".join(
        f"{name}: {type(b).__name__}" + (f" ({len(b.blocks)} blocks)" if b.composite else "")
        for name, b in children[:shown]
    )
    if len(children) > shown:
        blocks += f", … {len(children) - shown} more"
    ins = ", ".join(f"{n} -> {', '.join(map(str, t))}" for n, t in d.exposed_inputs.items())
    outs = ", ".join(f"{n} <- {end}" for n, end in d.exposed_outputs.items())
    label = f" {d.name!r}" if d.name else ""
    return f"<{type(d).__name__}{label} blocks=[{blocks}] inputs=({ins}) outputs=({outs})>"
