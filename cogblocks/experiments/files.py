"""Diagrams as files: plain data (JSON, or YAML with PyYAML) naming catalogue blocks, their parameters and wires.

A block is stored by its catalogue name (:func:`cogblocks.catalogue.public_blocks`) and the
arguments it was constructed with (:attr:`cogblocks.sim.Block.init_arguments`), as plain data:
arrays as nested lists with their dtype, signal specs as their fields, blocks given to a block
(``L2Sync(motion=...)``, ``L1(estimator=...)``) as nested block entries. Libraries, w̃ tables and
networks go to files beside the diagram (``<name>.data/``: ``.npz`` without pickles, ``.pt`` state
dicts loaded with ``weights_only=True``). No code is stored and nothing is evaluated when loading.

The L3 policies of an :class:`~cogblocks.sync.OscillatorMotion` are stored too: the DQN
policy by its network's state dict, the look-ahead policy by its model (plain data).

What cannot be saved, with a ``TypeError`` naming the block and the parameter: callables
(:class:`~cogblocks.blocks.Function`), ``numpy.random.Generator`` seeds (give an int seed),
python-control systems (:class:`~cogblocks.blocks.DiscreteLTI`), policies other than those two,
and any block or diagram subclass outside the catalogue (pass ``blocks={"Name": cls}`` to allow
your own).

A file holds a diagram's configuration, not its run state: a loaded diagram starts from tick 0.
The architecture blocks (``L2Sync``, ``L2Amplification``) are stored by their constructor
arguments, so changes made inside them after construction (``replace``) are refused.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from cogblocks.experiments.attachments import (
    KINDS,
    Attachment,
    attachment_for,
    attachments,
    lookahead_fields,
    lookahead_policy,
)
from cogblocks.sim import Block, Diagram, DiagramError, Signal

__all__ = ["FORMAT", "diagram_from_dict", "diagram_to_dict", "load_diagram", "save_diagram"]

FORMAT = "cogblocks.diagram/1"


def _catalogue(extra: Mapping[str, type] | None) -> dict[str, type]:
    from cogblocks.catalogue import public_blocks

    found: dict[str, type] = dict(public_blocks())
    found.update(extra or {})
    return found


class _Writer:
    """Turns values into plain data; writes data objects and networks to ``folder`` once each."""

    def __init__(self, catalogue: dict[str, type], folder: Path | None) -> None:
        self.names = {cls: name for name, cls in catalogue.items()}
        self.folder = folder
        self.written: dict[int, dict[str, str]] = {}

    def block(self, block: Block, where: str) -> dict[str, Any]:
        if type(block) is Diagram:
            entry: dict[str, Any] = {"diagram": self.diagram(block, where)}
        else:
            name = self.names.get(type(block))
            if name is None:
                raise TypeError(
                    f"{where}: {type(block).__name__} is not in the block catalogue "
                    "(cogblocks.catalogue.public_blocks()); pass blocks={name: class} to save it"
                )
            params = block.init_arguments
            if isinstance(block, Diagram):
                _check_unchanged(block, params, where)
            entry = {"type": name, "params": {k: self.value(v, f"{where}: parameter {k!r}") for k, v in params.items()}}
        if block.period is not None:
            entry["period"] = block.period
        return entry

    def diagram(self, diagram: Diagram, where: str) -> dict[str, Any]:
        prefix = f"{where}." if where else ""
        blocks = {name: self.block(child, f"{prefix}{name}") for name, child in diagram.blocks.items()}
        return {
            "blocks": blocks,
            "wires": [[str(source), str(target)] for source, target in diagram.wires],
            "inputs": {
                name: {"targets": [str(end) for end in targets], "spec": _spec(diagram.inputs[name].spec)}
                for name, targets in diagram.exposed_inputs.items()
            },
            "outputs": {name: str(end) for name, end in diagram.exposed_outputs.items()},
        }

    def value(self, value: Any, where: str) -> Any:
        if value is None or isinstance(value, (bool, int, float, str)):
            return value
        if isinstance(value, np.generic) and not isinstance(value, np.object_):
            return value.item()
        if isinstance(value, np.ndarray) and value.dtype.kind in "biuf":
            return {"array": value.tolist(), "dtype": value.dtype.str}
        if isinstance(value, tuple):
            return {"tuple": [self.value(v, where) for v in value]}
        if isinstance(value, list):
            return [self.value(v, where) for v in value]
        if isinstance(value, dict) and all(isinstance(k, str) for k in value):
            return {"dict": {k: self.value(v, f"{where}[{k!r}]") for k, v in value.items()}}
        if isinstance(value, Signal):
            return {"signal": _spec(value)}
        if isinstance(value, Block):
            return {"block": self.block(value, where)}
        attached = attachment_for(value)
        if attached is not None:
            return self.file(value, *attached, where)
        lookahead = lookahead_fields(value)
        if lookahead is not None:
            return {"policy": "LookaheadPolicy", **{k: self.value(v, f"{where}: {k}") for k, v in lookahead.items()}}
        raise TypeError(f"{where}: a {type(value).__name__} cannot be stored in a diagram file (no code is stored)")

    def file(self, value: Any, name: str, attachment: Attachment, where: str) -> dict[str, str]:
        if id(value) not in self.written:
            if self.folder is None:
                raise TypeError(f"{where}: a {name} is stored in a file beside the diagram; use save_diagram")
            relative = f"{self.folder.name}/{name.lower()}{len(self.written)}{attachment.suffix}"
            self.folder.mkdir(parents=True, exist_ok=True)
            attachment.write(value, self.folder.parent / relative)
            self.written[id(value)] = {attachment.kind: name, "file": relative}
        return self.written[id(value)]


def _check_unchanged(diagram: Diagram, params: dict[str, Any], where: str) -> None:
    """An architecture block is rebuilt from its arguments: refuse one whose insides were swapped since."""
    children = {id(c) for c in diagram.blocks.values()}
    swapped = [k for k, v in params.items() if isinstance(v, Block) and id(v) not in children]
    if swapped:
        raise TypeError(
            f"{where}: {type(diagram).__name__} was changed after construction (its {swapped} is no longer inside); "
            "build it again with the new block instead of replace() to save it"
        )


def _spec(spec: Signal) -> dict[str, Any]:
    return {
        "shape": None if spec.shape is None else list(spec.shape),
        "dtype": None if spec.dtype is None else spec.dtype.str,
        "unit": spec.unit,
        "wrapped": spec.wrapped,
    }


def diagram_to_dict(diagram: Diagram, *, blocks: Mapping[str, type] | None = None) -> dict[str, Any]:
    """A diagram as plain data (no libraries, tables or networks: those need :func:`save_diagram`).

    Parameters
    ----------
    diagram : Diagram
    blocks : mapping of str to type, optional
        Block classes outside the catalogue that may be stored, by the name to store them under.

    Raises
    ------
    TypeError
        If a block or a parameter cannot be stored; the message names the block and the parameter.
    """
    return _to_dict(diagram, blocks, None)


def _to_dict(diagram: Diagram, blocks: Mapping[str, type] | None, folder: Path | None) -> dict[str, Any]:
    if not isinstance(diagram, Diagram):
        raise TypeError(f"expected a Diagram, got {type(diagram).__name__}")
    writer = _Writer(_catalogue(blocks), folder)
    return {"format": FORMAT, "root": writer.block(diagram, "")}


class _Reader:
    """Builds blocks from plain data; every error names the file and the block."""

    def __init__(self, catalogue: dict[str, type], base: Path | None, source: str) -> None:
        self.catalogue = catalogue
        self.base = base
        self.source = source
        self.loaded: dict[str, Any] = {}

    def fail(self, where: str, exc: Exception) -> Exception:
        place = f" block {where!r}:" if where else ""
        message = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
        error = type(exc)(f"{self.source}:{place} {message}")
        error.__cause__ = exc
        return error

    def block(self, entry: Any, where: str) -> Block:
        if not isinstance(entry, dict) or ("diagram" in entry) == ("type" in entry):
            raise self.fail(where, ValueError("a block entry needs either 'type' and 'params' or 'diagram'"))
        if "diagram" in entry:
            block: Block = self.diagram(entry["diagram"], where, entry.get("period"))
            return block
        name = entry["type"]
        cls = self.catalogue.get(name)
        if cls is None:
            raise self.fail(where, ValueError(f"unknown block type {name!r}; known: {sorted(self.catalogue)}"))
        raw = entry.get("params", {})
        if not isinstance(raw, dict):
            raise self.fail(where, ValueError(f"params must be a mapping, got {type(raw).__name__}"))
        params = {k: self.value(v, where) for k, v in raw.items()}
        try:
            block = cls(**params)
            if entry.get("period") is not None:
                block.period = entry["period"]
        except (ValueError, TypeError, DiagramError) as exc:
            raise self.fail(where, exc) from exc
        return block

    def diagram(self, data: Any, where: str, period: float | None) -> Diagram:
        if not isinstance(data, dict):
            raise self.fail(where, ValueError("a diagram entry must be a mapping"))
        unknown = set(data) - {"blocks", "wires", "inputs", "outputs"}
        if unknown:
            raise self.fail(where, ValueError(f"unknown diagram field(s) {sorted(unknown)}"))
        prefix = f"{where}." if where else ""
        d = Diagram(period=period)
        children = {name: self.block(entry, f"{prefix}{name}") for name, entry in data.get("blocks", {}).items()}
        try:
            for name, child in children.items():
                d.add(name, child)
            for source, target in data.get("wires", []):
                d.connect(source, target)
            for name, exposed in data.get("inputs", {}).items():
                d.expose_input(name, *exposed["targets"], spec=_signal(exposed["spec"]))
            for name, source in data.get("outputs", {}).items():
                d.expose_output(name, source)
        except (ValueError, TypeError, DiagramError, KeyError) as exc:
            raise self.fail(where, exc) from exc
        return d

    def value(self, value: Any, where: str) -> Any:
        if isinstance(value, list):
            return [self.value(v, where) for v in value]
        if not isinstance(value, dict):
            return value
        if "array" in value:
            return np.array(value["array"], dtype=np.dtype(value["dtype"]))
        if "tuple" in value:
            return tuple(self.value(v, where) for v in value["tuple"])
        if "dict" in value:
            return {k: self.value(v, where) for k, v in value["dict"].items()}
        if "signal" in value:
            return _signal(value["signal"])
        if "block" in value:
            return self.block(value["block"], where)
        if value.get("policy") == "LookaheadPolicy":
            fields = {k: self.value(v, where) for k, v in value.items() if k != "policy"}
            try:
                return lookahead_policy(fields)
            except (ValueError, TypeError, KeyError) as exc:
                raise self.fail(where, exc) from exc
        if any(kind in value for kind in KINDS):
            return self.file(value, where)
        raise self.fail(where, ValueError(f"unknown parameter encoding with keys {sorted(value)}"))

    def file(self, value: dict[str, str], where: str) -> Any:
        relative = value["file"]
        if relative not in self.loaded:
            if self.base is None:
                raise self.fail(where, ValueError(f"{relative} is a file beside the diagram; use load_diagram"))
            kind = next(k for k in KINDS if k in value)
            attachment = attachments().get(value[kind])
            if attachment is None or attachment.kind != kind:
                raise self.fail(where, ValueError(f"unknown {kind} type {value[kind]!r}"))
            self.loaded[relative] = attachment.read(self.base / relative)
        return self.loaded[relative]


def _signal(fields: dict[str, Any]) -> Signal:
    shape = fields["shape"]
    return Signal(
        shape=None if shape is None else tuple(shape),
        dtype=fields["dtype"],
        unit=fields["unit"],
        wrapped=fields["wrapped"],
    )


def diagram_from_dict(
    data: Mapping[str, Any], *, blocks: Mapping[str, type] | None = None, source: str = "<dict>"
) -> Diagram:
    """Build the diagram that :func:`diagram_to_dict` described.

    Raises
    ------
    ValueError, TypeError, DiagramError
        What building the same diagram in Python raises, with ``source`` and the block's path
        in front of the message.
    """
    return _from_dict(data, blocks, None, source)


def _from_dict(data: Mapping[str, Any], blocks: Mapping[str, type] | None, base: Path | None, source: str) -> Diagram:
    if not isinstance(data, Mapping) or data.get("format") != FORMAT:
        found = data.get("format") if isinstance(data, Mapping) else type(data).__name__
        raise ValueError(f"{source}: not a cogblocks diagram (format {found!r}, expected {FORMAT!r})")
    root = _Reader(_catalogue(blocks), base, source).block(data["root"], "")
    if not isinstance(root, Diagram):
        raise ValueError(f"{source}: the root entry is a {type(root).__name__}, not a diagram")
    return root


def _is_yaml(path: Path) -> bool:
    return path.suffix.lower() in (".yaml", ".yml")


def save_diagram(diagram: Diagram, path: str | Path, *, blocks: Mapping[str, type] | None = None) -> Path:
    """Write ``diagram`` to ``path`` (``.json``, or ``.yaml``/``.yml`` with PyYAML).

    Libraries, tables and networks go to ``<path stem>.data/`` beside it. Returns the path.
    """
    path = Path(path)
    data = _to_dict(diagram, blocks, path.parent / f"{path.stem}.data")
    if _is_yaml(path):
        import yaml

        path.write_text(yaml.safe_dump(data, sort_keys=False))
    else:
        path.write_text(json.dumps(data, indent=1))
    return path


def load_diagram(path: str | Path, *, blocks: Mapping[str, type] | None = None) -> Diagram:
    """Read a diagram written by :func:`save_diagram`; errors name the file and the block."""
    path = Path(path)
    try:
        text = path.read_text()
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not a diagram file (not text: {exc.reason} at byte {exc.start})") from None
    if _is_yaml(path):
        import yaml

        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ValueError(f"{path}: not readable as YAML: {exc}") from exc
    else:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: not readable as JSON: {exc}") from exc
    return _from_dict(data, blocks, path.parent, str(path))
