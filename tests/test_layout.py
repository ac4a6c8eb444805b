"""The package layout keeps its rules: layers import only downwards, no import cycles, short modules.

Imports are read from the source (``ast``), counting imports inside functions, ``importlib.import_module``
calls with a literal name and the ``_LAZY`` tables of lazily loading packages; only imports under
``if TYPE_CHECKING:`` (never executed) are left out. An edge goes to the module an import names
(``from cogblocks.sync import Blender`` is an edge to the package ``cogblocks.sync``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent / "cogblocks"

#: What each layer may import from cogblocks besides itself. Lower layers never import higher ones.
ALLOWED = {
    "sim": set(),
    "data": {"sim"},
    "blocks": {"sim", "data"},
    "sensing": {"sim", "data", "blocks"},
    "phase": {"sim", "data", "blocks", "sensing"},
    "sync": {"sim", "data", "blocks"},
    "amplification": {"sim", "data", "blocks"},
    "analysis": {"sim", "data", "blocks", "sync"},
    "catalogue": {"sim", "blocks", "sensing", "phase", "sync", "amplification"},
    "diagrams": {"sim", "data", "blocks", "sensing", "phase", "sync", "amplification"},
    "training": {"sim", "data", "blocks", "sync", "amplification", "diagrams"},
    "live": {"sim", "data", "blocks", "sensing", "phase", "sync", "diagrams", "cli_options"},
    "experiments": {
        "sim",
        "data",
        "blocks",
        "sensing",
        "phase",
        "sync",
        "amplification",
        "diagrams",
        "training",
        "catalogue",
        "analysis",
        "evaluation",
        "cli_options",
    },
    "evaluation": {"sim", "data", "blocks", "sensing", "phase", "sync", "amplification", "analysis", "diagrams"},
    "cli_options": {"sim", "diagrams"},
    "cli": {
        "cli_options",
        "sim",
        "data",
        "blocks",
        "sensing",
        "phase",
        "sync",
        "amplification",
        "diagrams",
        "training",
        "live",
        "experiments",
        "analysis",
        "evaluation",
        "catalogue",
        "",
    },
    "": {"sim"},  # cogblocks/__init__.py re-exports the engine's main names
}

#: Modules allowed past 400 lines (up to 450), each one idea that does not split sensibly.
LONG_MODULES = {
    "cogblocks.sim.compiled": "the compiled plan: flattening, ordering, binding and the tick loop share private state",
    "cogblocks.sensing.kalman": "KalmanEstimator and fit_noise, the maximum-likelihood fit of its own noise model",
    "cogblocks.data.reach": "the seeded synthetic reach-to-grasp library and its container",
}


def _modules() -> dict[str, Path]:
    out = {}
    for path in ROOT.rglob("*.py"):
        parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _type_checking_only(tree: ast.AST) -> set[int]:
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    return skip


def _target(name: str) -> str | None:
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def imports_of(module: str) -> set[str]:
    tree = ast.parse(MODULES[module].read_text())
    skip = _type_checking_only(tree)
    found: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            # "from package import submodule" imports the submodule
            found |= {
                f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in MODULES else node.module for a in node.names
            }
        elif isinstance(node, ast.Call) and ast.unparse(node.func).endswith(("import_module", "forwarding")):
            # import_module(name) and a moved module's forwarding(__name__, new) name the module they load
            found |= {a.value for a in node.args if isinstance(a, ast.Constant) and isinstance(a.value, str)}
        elif isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "_LAZY" for t in node.targets):
            found |= {v.value for v in node.value.values if isinstance(v, ast.Constant)}
    return {t for t in map(_target, (f for f in found if f.startswith("cogblocks"))) if t and t != module}


GRAPH = {m: imports_of(m) for m in MODULES}


def layer(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


#: Old import paths of modules that moved up a layer: each only forwards, with a DeprecationWarning, to its new place.
MOVED = {
    "cogblocks.analysis.sync_bound": "cogblocks.evaluation.sync_bound",
    "cogblocks.phase.evaluation1d": "cogblocks.evaluation.phase1d",
    "cogblocks.experiments.sync_heldout": "cogblocks.evaluation.sync_heldout",
}


def test_every_layer_imports_only_the_layers_below_it():
    assert set(map(layer, MODULES)) <= set(ALLOWED), "a new package needs its row in ALLOWED"
    wrong = sorted(
        f"{m} imports {t}"
        for m, ts in GRAPH.items()
        for t in ts
        if layer(t) != layer(m) and layer(t) not in ALLOWED[layer(m)] and MOVED.get(m) != t
    )
    assert not wrong, "\n".join(wrong)


def test_the_engine_imports_nothing_else_from_cogblocks():
    assert not {t for m, ts in GRAPH.items() if layer(m) == "sim" for t in ts if layer(t) != "sim"}


def _cycles() -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(GRAPH):
        if v not in index:
            visit(v)
    return found


def test_no_import_cycle_between_cogblocks_modules():
    assert _cycles() == []


def test_the_cycle_finder_finds_a_cycle():
    GRAPH["cogblocks.sim.signal"].add("cogblocks.sim.trace")
    GRAPH["cogblocks.sim.trace"].add("cogblocks.sim.signal")
    try:
        assert ["cogblocks.sim.signal", "cogblocks.sim.trace"] in _cycles()
    finally:
        GRAPH["cogblocks.sim.signal"].discard("cogblocks.sim.trace")
        GRAPH["cogblocks.sim.trace"].discard("cogblocks.sim.signal")


def test_a_moved_module_only_forwards_to_its_new_place():
    for old, new in MOVED.items():
        assert GRAPH[old] - {"cogblocks.sim.moved"} == {new}, f"{old} should only forward to {new}"
        assert "DeprecationWarning" in MODULES[old].read_text()


def test_a_lazy_import_counts_as_an_import():
    assert "cogblocks.sync.dqn_policy" in GRAPH["cogblocks.sync"]
    assert "cogblocks.analysis.linearization" in GRAPH["cogblocks.analysis"]


@pytest.mark.parametrize("module", sorted(MODULES))
def test_modules_stay_short(module):
    n = len(MODULES[module].read_text().splitlines())
    limit = 450 if module in LONG_MODULES else 400
    assert n <= limit, f"{module} has {n} lines (limit {limit})"
