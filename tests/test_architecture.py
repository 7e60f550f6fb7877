"""The import graph the layout promises (README, docs/method.md), read from the source with `ast`.

- `assets` depends on nothing of ours; no stage of `pipelines` imports `twin`; nothing in the product
  imports the test-data generator (`pipelines.synth`) or the benchmarks;
- no module imports another module's private (underscore) name;
- the product reaches identification through its face, `pipelines.identify`, never into its modules;
- no module-level import cycle (imports inside functions are allowed to defer heavy libraries);
- no source file over 600 lines.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("assets", "exporters", "pipelines", "twin", "benchmarks")
PRODUCT = ("assets", "exporters", "pipelines", "twin")


def _modules() -> dict[str, Path]:
    out = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


MODULES = _modules()


def _imports(module: str, top_level_only: bool = False) -> list[tuple[str, str]]:
    """(imported module, name or "") of every import of ours in `module`."""
    path = MODULES[module]
    tree = ast.parse(path.read_text())
    nodes = tree.body if top_level_only else ast.walk(tree)
    out = []
    for node in nodes:
        if isinstance(node, ast.ImportFrom):
            if node.level:
                package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
                base = ".".join(package[:len(package) - node.level + 1] + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            for alias in node.names:
                full = f"{base}.{alias.name}"
                out.append((full if full in MODULES else base, alias.name))
        elif isinstance(node, ast.Import):
            out += [(alias.name, "") for alias in node.names]
    return [(m, n) for m, n in out if m.split(".")[0] in PACKAGES]


def test_layers():
    wrong = []
    for module in MODULES:
        top = module.split(".")[0]
        for target, _ in _imports(module):
            if top == "assets" and not target.startswith("assets"):
                wrong.append(f"{module} -> {target} (assets depends on nothing of ours)")
            if top == "pipelines" and target.startswith("twin"):
                wrong.append(f"{module} -> {target} (a stage imports the application)")
            if (top in PRODUCT and not module.startswith("pipelines.synth") and target.startswith("pipelines.synth")
                    and not module.startswith("twin.cli")):
                wrong.append(f"{module} -> {target} (the product imports the test-data generator)")
            if top in PRODUCT and target.startswith("benchmarks"):
                wrong.append(f"{module} -> {target} (the product imports the benchmarks)")
    assert not wrong, "\n".join(wrong)


def test_no_private_names_across_modules():
    wrong = [f"{module} imports {name} from {target}" for module in MODULES for target, name in _imports(module)
             if name.startswith("_") and not name.startswith("__") and target != module]
    assert not wrong, "\n".join(wrong)


def test_identification_reached_through_its_face():
    inside = [f"{m} -> {t}" for m in MODULES if m.split(".")[0] in PRODUCT and not m.startswith("pipelines.identify")
              for t, _ in _imports(m) if t.startswith("pipelines.identify.")]
    assert not inside, "import from pipelines.identify instead:\n" + "\n".join(inside)


def test_no_import_cycle_at_module_level():
    graph = {m: {t if t in MODULES else t.rsplit(".", 1)[0] for t, _ in _imports(m, top_level_only=True)} & set(MODULES)
             for m in MODULES}
    # a package's __init__ importing its own submodules is its public face, not a cycle
    graph = {m: {t for t in ts if not t.startswith(m + ".")} for m, ts in graph.items()}
    state: dict[str, int] = {}

    def visit(m, path):
        state[m] = 1
        for t in graph[m]:
            if state.get(t) == 1:  # on the current path
                pytest.fail("import cycle: " + " -> ".join(path[path.index(t):] + [t]))
            if t not in state:
                visit(t, path + [t])
        state[m] = 2

    for m in MODULES:
        if m not in state:
            visit(m, [m])


def test_no_source_file_over_600_lines():
    long = {str(p.relative_to(ROOT)): n for p in MODULES.values() if (n := len(p.read_text().splitlines())) > 600}
    assert not long, long
