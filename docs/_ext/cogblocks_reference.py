"""Sphinx extension: the generated reference of cogblocks (API pages, block port tables, the CLI).

The API pages are written at build time from the package itself, so that a renamed or new module
appears without editing the docs: every subpackage of ``cogblocks`` that declares ``__all__`` gets
one page listing those names; a subpackage without one gets its public modules' ``__all__``.
A block's entry carries a table of its ports read from the block's declaration (see
:func:`declared_ports`), and ``cogblocks-cli`` renders every command of the argparse parser.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import inspect
import os
import pkgutil
import re
import textwrap
from pathlib import Path
from typing import Any

from docutils import nodes
from docutils.parsers.rst import Directive, directives
from docutils.statemachine import StringList
from sphinx.application import Sphinx
from sphinx.util.nodes import nested_parse_with_titles

PACKAGE = "cogblocks"
OUT = "reference/api"  # relative to the source directory; generated, not committed


# -- which names are public -------------------------------------------------------------------
def _public_modules(package: str) -> list[str]:
    mod = importlib.import_module(package)
    if not hasattr(mod, "__path__"):
        return []
    return sorted(
        f"{package}.{info.name}" for info in pkgutil.iter_modules(mod.__path__) if not info.name.startswith("_")
    )


def api_pages() -> dict[str, list[tuple[str, list[str]]]]:
    """Each reference page (a subpackage, or the top-level modules) and the names it documents.

    Returns
    -------
    dict
        ``{page: [(module, [name, ...]), ...]}``: the module a name is documented under (its
        package when the package exports it) and the names, in ``__all__`` order.
    """
    pages: dict[str, list[tuple[str, list[str]]]] = {}
    top: list[tuple[str, list[str]]] = [(PACKAGE, list(importlib.import_module(PACKAGE).__all__))]
    for name in _public_modules(PACKAGE):
        mod = importlib.import_module(name)
        if name == f"{PACKAGE}.cli":
            continue  # the CLI has its own page, rendered from its parser
        if hasattr(mod, "__path__"):
            if getattr(mod, "__all__", None):
                pages[name] = [(name, [n for n in mod.__all__ if not n.startswith("_")])]
            else:
                entries = []
                for sub in _public_modules(name):
                    names = getattr(importlib.import_module(sub), "__all__", None)
                    if names:
                        entries.append((sub, list(names)))
                if entries:
                    pages[name] = entries
        elif getattr(mod, "__all__", None):
            top.append((name, list(mod.__all__)))
    pages[PACKAGE] = top
    return dict(sorted(pages.items()))


def _is_block(obj: Any) -> bool:
    from cogblocks.sim import Block

    return inspect.isclass(obj) and issubclass(obj, Block) and obj is not Block


def _attr_doc(module: str, name: str) -> list[str]:
    """The ``#:`` comment documenting a module-level name, if its module has one."""
    from sphinx.pycode import ModuleAnalyzer

    mod = importlib.import_module(module)
    for candidate in (module, getattr(getattr(mod, name), "__module__", None) or module):
        try:
            docs = ModuleAnalyzer.for_module(candidate).find_attr_docs()
        except Exception:  # a module without source: no comment to show
            continue
        if ("", name) in docs:
            return list(docs[("", name)])
    return []


def _entry(module: str, name: str, canonical: bool) -> list[str]:
    obj = getattr(importlib.import_module(module), name)
    target = f"{module}.{name}"
    index = [] if canonical else ["   :no-index:"]
    if inspect.isclass(obj):
        if _is_block(obj):  # a block's methods are the engine's business; its ports are the user's
            return [f".. autoclass:: {target}", *index, "", f".. cogblocks-ports:: {target}", ""]
        return [f".. autoclass:: {target}", "   :members:", *index, ""]
    if callable(obj):
        return [f".. autofunction:: {target}", *index, ""]
    doc = _attr_doc(module, name) or [f"A ``{type(obj).__name__}``."]
    return [f".. py:data:: {target}", *index, "", *[f"   {line}" for line in doc], ""]


def _summary(obj: Any) -> str:
    """The first paragraph of a docstring, on one line (whole, so that no inline markup is cut)."""
    first = (inspect.getdoc(obj) or "").split("\n\n")[0]
    return " ".join(first.split()) or "(no description)"


def _canonical_page(obj: Any, pages: list[str]) -> str | None:
    """The page whose package defines ``obj``: the longest page name that prefixes its module."""
    module = getattr(obj, "__module__", None) or ""
    owners = [p for p in pages if module == p or module.startswith(p + ".")]
    return max(owners, key=len) if owners else None


def write_api_pages(app: Sphinx) -> None:
    """Write one page per subpackage under ``reference/api/`` and their index."""
    out = Path(app.srcdir) / OUT
    out.mkdir(parents=True, exist_ok=True)
    pages = api_pages()
    wanted = {f"{page}.rst" for page in pages} | {"index.rst"}
    for old in out.glob("*.rst"):
        if old.name not in wanted:
            old.unlink()
    for page, entries in pages.items():
        first = (importlib.import_module(page).__doc__ or "").strip().splitlines()
        lines = [f"``{page}``", "=" * (len(page) + 4), ""]
        if first:
            lines += [first[0], ""]
        for module, names in entries:
            if module != page:
                lines += [f"``{module}``", "-" * (len(module) + 4), ""]
            mod = importlib.import_module(module)
            listed = [n for n in names if inspect.isclass(getattr(mod, n)) or callable(getattr(mod, n))]
            lines += [f".. currentmodule:: {module}", ""]
            lines += [f"- :obj:`{n}`: {_summary(getattr(mod, n))}" for n in listed] + [""]
            for n in names:
                obj = getattr(mod, n)
                owner = _canonical_page(obj, list(pages)) if inspect.isclass(obj) or callable(obj) else page
                lines += _entry(module, n, canonical=owner in (page, None))
        _write_if_changed(out / f"{page}.rst", "\n".join(lines))
    index = ["API", "===", "", ".. toctree::", "   :maxdepth: 1", ""] + [f"   {p}" for p in pages]
    _write_if_changed(out / "index.rst", "\n".join(index) + "\n")


def _write_if_changed(path: Path, text: str) -> None:
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


# -- ports of a block, from its declaration --------------------------------------------------
_FIELDS = ("shape", "unit", "wrapped")


def _source(node: ast.AST | None) -> str:
    return "" if node is None else ast.unparse(node)


def _signal_fields(spec: ast.AST, namespace: dict[str, Any]) -> dict[str, str] | None:
    """Shape, unit and wrapping of a spec expression, as source text; None when it is not a Signal.

    ``Signal(...)`` is read field by field; a named spec (``PHASE``) is looked up in the block's
    module; ``NAMED.with_(field=...)`` is the named spec with those fields replaced.
    """
    from cogblocks.sim import Signal

    if isinstance(spec, ast.Call) and _source(spec.func).endswith("Signal"):
        given = {kw.arg: _source(kw.value) for kw in spec.keywords}
        for i, arg in enumerate(spec.args[:2]):
            given[("shape", "dtype")[i]] = _source(arg)
        defaults = {"shape": "()", "unit": "'1'", "wrapped": "False"}
        return {f: given.get(f, defaults[f]) for f in _FIELDS}
    if isinstance(spec, ast.Call) and isinstance(spec.func, ast.Attribute) and spec.func.attr == "with_":
        base = _signal_fields(spec.func.value, namespace)
        if base is None:
            return None
        return {**base, **{kw.arg: _source(kw.value) for kw in spec.keywords if kw.arg in _FIELDS}}
    try:
        value = eval(compile(ast.Expression(spec), "<spec>", "eval"), dict(namespace))  # a module constant
    except Exception:  # computed from the block's parameters: shown as written
        return None
    if isinstance(value, Signal):
        return {f: repr(getattr(value, f)) for f in _FIELDS}
    return None


def _spec_fields(call: ast.Call, namespace: dict[str, Any]) -> dict[str, str]:
    """The spec fields of one ``add_input``/``add_output`` call, as source text."""
    fields: dict[str, str] = {}
    spec = call.args[1] if len(call.args) > 1 else None
    for kw in call.keywords:
        if kw.arg == "spec":
            spec = kw.value
    if spec is not None:
        read = _signal_fields(spec, namespace)
        if read is None:
            fields["spec"] = _source(spec)
        else:
            fields.update(read)
    for kw in call.keywords:
        if kw.arg in _FIELDS or kw.arg in ("like", "feedthrough", "default"):
            fields[kw.arg] = _source(kw.value)
    return fields


def declared_ports(cls: type) -> list[dict[str, str]]:
    """The ports a block class declares, read from the ``add_input``/``add_output`` calls of its code.

    Each port is reported as written: literal specs as values, specs computed from the block's
    parameters as the expression that computes them (``(n,)``, ``unit``). Methods of the class
    and its bases (up to :class:`~cogblocks.sim.Block`) are read, so ports declared in a helper
    method or an inherited ``__init__`` appear too.
    """
    from cogblocks.sim import Block

    ports: list[dict[str, str]] = []
    seen: set[tuple[str, str]] = set()
    for klass in cls.__mro__:
        if klass is Block or not issubclass(klass, Block):
            continue
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(klass)))
        except (OSError, TypeError, SyntaxError):
            continue
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)):
                continue
            if node.func.attr not in ("add_input", "add_output") or not node.args:
                continue
            name = node.args[0]
            label = name.value if isinstance(name, ast.Constant) else f"{{{_source(name)}}}"
            direction = "input" if node.func.attr == "add_input" else "output"
            if (direction, label) in seen:
                continue
            seen.add((direction, label))
            namespace = vars(importlib.import_module(klass.__module__))
            ports.append({"port": str(label), "direction": direction, **_spec_fields(node, namespace)})
    return ports


def _policy(cls: type) -> str:
    """The docstring's bad-data policy paragraph (from "Bad data policy:" to the next blank line), or ``""``."""
    doc = inspect.getdoc(cls) or ""
    match = re.search(r"Bad[ -]data policy:(.*?)(?:\n\s*\n|$)", doc, re.S | re.I)
    return " ".join(match.group(1).split()) if match else ""


class PortsDirective(Directive):
    """``.. cogblocks-ports:: package.Block``: a table of the block's declared ports and its bad-data policy."""

    required_arguments = 1
    has_content = False

    def run(self) -> list[nodes.Node]:
        module, _, name = self.arguments[0].rpartition(".")
        cls = getattr(importlib.import_module(module), name)
        ports = declared_ports(cls)
        lines = [f".. rubric:: Ports of {name}", ""]
        if ports:
            lines += [
                ".. list-table::",
                "   :header-rows: 1",
                "",
                "   * - port",
                "     - direction",
                "     - shape",
                "     - unit",
                "     - wrapped",
                "     - notes",
            ]
            for p in ports:
                notes = []
                if "like" in p:
                    notes.append(f"spec like input {p['like']}")
                if "spec" in p:
                    notes.append(f"spec ``{p['spec']}``")
                if p.get("feedthrough") == "False":
                    notes.append("not feedthrough (read only by ``update``)")
                if "default" in p:
                    notes.append(f"default ``{p['default']}``")
                cells = [f"``{p['port']}``", p["direction"]]
                cells += [("any" if p[f] == "None" else f"``{p[f]}``") if f in p else "generic" for f in _FIELDS]
                cells.append("; ".join(notes) or " ")
                lines.append(f"   * - {cells[0]}")
                lines += [f"     - {c}" for c in cells[1:]]
            lines += [
                "",
                "Shapes, units and wrapping written as an expression are computed from the "
                "block's parameters; *generic* takes the spec of whatever drives the input; *any* accepts "
                "any value of that field.",
                "",
            ]
        else:
            lines += ["Ports are declared from the block's parameters; see its description.", ""]
        policy = _policy(cls)
        lines += [
            f"**Bad data.** {policy.split(':', 1)[1].strip() if ':' in policy else policy}"
            if policy
            else "**Bad data.** No policy stated: finite outputs are expected.",
            "",
        ]
        content = StringList(lines, source=f"cogblocks-ports {self.arguments[0]}")
        container = nodes.container()
        nested_parse_with_titles(self.state, content, container)
        return container.children


class CatalogueDirective(Directive):
    """``.. cogblocks-catalogue::``: every public block (``cogblocks.catalogue``) by package, one line each."""

    def run(self) -> list[nodes.Node]:
        from cogblocks import catalogue

        by_package: dict[str, list[type]] = {}
        for cls in catalogue.public_blocks().values():
            by_package.setdefault(catalogue.package_of(cls), []).append(cls)
        lines: list[str] = []
        for package in catalogue.PACKAGES:
            lines += [
                f".. rubric:: ``{package}``",
                "",
                ".. list-table::",
                "   :header-rows: 1",
                "",
                "   * - block",
                "     - inputs → outputs",
                "     - what it does",
            ]
            for cls in by_package.get(package, []):
                ports = declared_ports(cls)
                ins = ", ".join(f"``{p['port']}``" for p in ports if p["direction"] == "input") or "—"
                outs = ", ".join(f"``{p['port']}``" for p in ports if p["direction"] == "output") or "—"
                summary = (inspect.getdoc(cls) or "").split("\n\n")[0].replace("\n", " ")
                lines += [f"   * - :class:`~{package}.{cls.__name__}`", f"     - {ins} → {outs}", f"     - {summary}"]
            lines.append("")
        content = StringList(lines, source="cogblocks-catalogue")
        container = nodes.container()
        nested_parse_with_titles(self.state, content, container)
        return container.children


# -- the CLI -----------------------------------------------------------------------------------
def _commands(parser: argparse.ArgumentParser, prefix: str) -> list[tuple[str, argparse.ArgumentParser]]:
    found = [(prefix, parser)]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found += _commands(sub, f"{prefix} {name}")
    return found


class CliDirective(Directive):
    """``.. cogblocks-cli:: module:function``: every command of an argparse parser with its help."""

    required_arguments = 1
    option_spec = {"prog": directives.unchanged}

    def run(self) -> list[nodes.Node]:
        module, _, func = self.arguments[0].partition(":")
        os.environ["COLUMNS"] = "100"  # argparse wraps to the terminal; fix it so the page is stable
        parser = getattr(importlib.import_module(module), func)()
        out: list[nodes.Node] = []
        for command, sub in _commands(parser, parser.prog):
            section = nodes.section(ids=[nodes.make_id(command)])
            section += nodes.title(text=command)
            block = nodes.literal_block(text=sub.format_help())
            block["language"] = "text"  # help text, not Python: no highlighting
            section += block
            out.append(section)
        return out


def setup(app: Sphinx) -> dict[str, Any]:
    app.connect("builder-inited", write_api_pages)
    app.add_directive("cogblocks-ports", PortsDirective)
    app.add_directive("cogblocks-cli", CliDirective)
    app.add_directive("cogblocks-catalogue", CatalogueDirective)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
