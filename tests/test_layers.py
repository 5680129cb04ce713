"""The house keeps its shape (docs/architecture.md rule 16): the packages import only
downwards, and no two modules import each other, directly or round a circle.

The layers, lowest first (a module may import its own layer and the ones below):

====  =====================================================================
0     ``cnt_env`` (the package root), ``units``, ``presets``, ``io``
1     ``cnt_env.rod`` (DER kernels)
2     ``cnt_env.sim`` (forces, stepper, substrate, deposition, warm start)
3     ``cnt_env.patterns``, ``cnt_env.plotting``
4     ``cnt_env.task`` (the env, spaces, scoring, routes, raster)
5     ``cnt_env.runs``, ``cnt_env.sweep``
6     ``cnt_env.replay``
7     ``cnt_env.cli``, ``cnt_env.__main__``
8     ``policies``
9     ``training``
====  =====================================================================

Every ``import`` counts, at module level or inside a function: a deferred import that
hides a circle is still a circle. The walk uses ``ast``, so nothing is imported.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("cnt_env", "policies", "training")

#: module-name prefix -> layer; the longest matching prefix wins.
LAYERS: dict[str, int] = {
    "cnt_env": 0,
    "cnt_env.units": 0,
    "cnt_env.presets": 0,
    "cnt_env.io": 0,
    "cnt_env.jsonl": 0,
    "cnt_env.rod": 1,
    "cnt_env.sim": 2,
    "cnt_env.patterns": 3,
    "cnt_env.plotting": 3,
    "cnt_env.task": 4,
    "cnt_env.runs": 5,
    "cnt_env.sweep": 5,
    "cnt_env.replay": 6,
    "cnt_env.cli": 7,
    "cnt_env.__main__": 7,
    "policies": 8,
    "training": 9,
}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def layer_of(module: str) -> int:
    best = max((p for p in LAYERS if module == p or module.startswith(p + ".")), key=len)
    return LAYERS[best]


def project_modules() -> dict[str, Path]:
    mods = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            mods[module_name(path)] = path
    return mods


def imports_of(module: str, path: Path, known: set[str]) -> set[str]:
    """Project modules that ``module`` imports (resolving relative imports; ``from a
    import b`` counts as importing ``a.b`` when that is a module, else ``a``)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                prefix = ".".join(base + ([node.module] if node.module else []))
            else:
                prefix = node.module or ""
            names = [f"{prefix}.{alias.name}" for alias in node.names] + [prefix]
        else:
            continue
        for name in names:
            # the longest known module that the name starts with
            parts = name.split(".")
            for k in range(len(parts), 0, -1):
                cand = ".".join(parts[:k])
                if cand in known:
                    if cand != module:
                        found.add(cand)
                    break
    return found


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    mods = project_modules()
    known = set(mods)
    return {m: imports_of(m, p, known) for m, p in mods.items()}


def test_every_module_has_a_layer(graph: dict[str, set[str]]) -> None:
    assert graph, "no project modules found"
    for m in graph:
        assert any(m == p or m.startswith(p + ".") for p in LAYERS), m


def test_no_import_from_a_higher_layer(graph: dict[str, set[str]]) -> None:
    upward = [
        f"{m} (layer {layer_of(m)}) imports {t} (layer {layer_of(t)})"
        for m, targets in sorted(graph.items())
        for t in sorted(targets)
        if layer_of(t) > layer_of(m)
    ]
    assert not upward, "upward imports:\n" + "\n".join(upward)


def test_no_import_circle(graph: dict[str, set[str]]) -> None:
    # Package roots re-export their children; a child importing its package's
    # root for a sibling is not a circle of modules, so edges child -> own package
    # root are dropped before the search.
    edges = {m: {t for t in ts if not m.startswith(t + ".")} for m, ts in graph.items()}
    state: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for t in sorted(edges.get(m, ())):
            if state.get(t) == 1:
                cycles.append([*stack[stack.index(t) :], t])
            elif t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(edges):
        if m not in state:
            visit(m)
    assert not cycles, "import circles:\n" + "\n".join(" -> ".join(c) for c in cycles)


def test_the_walk_sees_upward_and_circular_imports(tmp_path: Path) -> None:
    """The checker itself can fail: a fake kernel module importing the env is caught."""
    fake = ROOT / "cnt_env" / "rod" / "banded.py"
    known = {"cnt_env.rod.banded", "cnt_env.task.env", "cnt_env.task"}
    src = tmp_path / "banded.py"
    src.write_text("from cnt_env.task.env import CNTDepositEnv\n")
    found = imports_of("cnt_env.rod.banded", src, known)
    assert found == {"cnt_env.task.env"}
    assert layer_of("cnt_env.task.env") > layer_of("cnt_env.rod.banded")
    assert fake.exists()
