"""The import graph of app/, core/, drivers/, calibration/ and slscan/ keeps its layers one way.

core/ (errors, file formats, patterns) imports nothing of ours but itself; drivers/ imports only
core/ and drivers/; slscan/ (the public API) sits on top: nothing else imports it; no module imports,
even lazily, one that imports it back. Every `.py` file is
parsed (nothing is imported), so a lazy import inside a function counts too.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("app", "core", "drivers", "calibration", "slscan")
KNOWN_EXCEPTIONS: set[tuple[str, str]] = set()  # (importer, imported) edges allowed against the layers


def _modules() -> dict[str, Path]:
    mods = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            mods[name] = path
    return mods


MODULES = _modules()


def _resolve(name: str) -> str | None:
    """The module of ours that `import name` loads last (a name inside a module -> that module)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _imports(module: str, path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parts = parts[: len(parts) - (node.level - 1)]
                base = ".".join([*parts, base] if base else parts)
            names = [base] + [f"{base}.{alias.name}" for alias in node.names]
        for name in names:
            target = _resolve(name)
            if target is not None and target != module:
                found.add(target)
    return found


GRAPH = {module: _imports(module, path) for module, path in MODULES.items()}


def _layer(module: str) -> str:
    return module.split(".")[0]


def test_the_graph_sees_the_packages():
    assert {"app.capture", "core.errors", "drivers.base", "calibration.session"} <= set(GRAPH)
    assert "core.errors" in GRAPH["drivers.base"] and "app.capture" in GRAPH["app.session"]


def test_core_imports_only_core():
    wrong = {(m, t) for m, ts in GRAPH.items() if _layer(m) == "core" for t in ts if _layer(t) != "core"}
    assert not wrong, sorted(wrong)


def test_drivers_import_nothing_from_app_or_calibration():
    wrong = {
        (m, t)
        for m, ts in GRAPH.items()
        if _layer(m) == "drivers"
        for t in ts
        if _layer(t) in ("app", "calibration") and (m, t) not in KNOWN_EXCEPTIONS
    }
    assert not wrong, sorted(wrong)


def test_calibration_does_not_reach_into_the_cli_or_the_view():
    wrong = {
        (m, t)
        for m, ts in GRAPH.items()
        if _layer(m) == "calibration"
        for t in ts
        if t.startswith(("app.commands", "app.view", "app.cli"))
    }
    assert not wrong, sorted(wrong)


def test_only_the_public_api_imports_the_public_api():
    wrong = {(m, t) for m, ts in GRAPH.items() if _layer(m) != "slscan" for t in ts if _layer(t) == "slscan"}
    assert not wrong, sorted(wrong)
    assert "app.decode.pipeline" in GRAPH["slscan.decoder"]


def test_no_import_cycles():
    """Tarjan's strongly connected components: any component of two or more modules is a cycle."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in sorted(GRAPH):
        if v not in index:
            visit(v)
    assert not cycles, cycles
