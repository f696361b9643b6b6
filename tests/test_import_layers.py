"""Layers import only downward, and no two modules import each other (directly or around a loop).

Every module of ``nerf2gs_plugin`` is read with ``ast`` (imports at the top, inside functions and
under ``if TYPE_CHECKING:`` alike), mapped to its layer, and each import of the package's own
modules is checked. The layers, bottom up (a module may import its own layer and those below):
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = "nerf2gs_plugin"
ROOT = Path(__file__).resolve().parents[1] / PACKAGE

# bottom up; a module's layer is that of the longest of these names that its dotted path under the
# package starts with (the package's own __init__ is the ground floor): a layer names a package, or
# one module of a package that sits on another floor than the rest of it.
LAYERS: list[tuple[str, ...]] = [
    ("", "utils", "errors", "progress", "warn"),
    ("cameras", "data"),
    ("masks", "rendering", "fields"),  # masks: mask files, segmenters, masks from renders, their evaluation
    ("datamanagers",),
    ("engine",),  # the contracts methods implement: Model, Pipeline, Trainer(Config), optimizers
    # MethodSpecification; built-in methods are named by string, not imported. runs: a trained run
    # loaded back, its method found in the registry
    ("registry", "runs"),
    ("methods",),
    # the features that train or load runs: the augmentation (its reference is a run), the enhancer,
    # and masking (ns2gs-data masks: a segmenter's masks, or masks from a first reference of the capture)
    ("augment", "enhancer", "masking"),
    ("eval", "render", "blocks"),  # blocks: city-block partition of a capture and merge of the block runs;
    # render: camera paths, videos and the measures from above (eval reports them)
    ("viewer", "cli"),
]
RANK = {name: i for i, names in enumerate(LAYERS) for name in names}

ALLOWED_UPWARD: set[tuple[str, str]] = set()  # none: every arrow points down

# packages whose modules sit on more than one floor (a layer above names some of their modules); every
# other package is one room on one floor, so a feature that needs a lower part of it means that part
# belongs lower (the image metrics the enhancer trains with live in utils, not eval)
SPLIT_PACKAGES: set[str] = set()


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def all_modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(ROOT.rglob("*.py"))}


def imports_of(name: str, path: Path, modules: dict[str, Path], package: str = PACKAGE) -> set[str]:
    """The package's modules that ``name`` imports anywhere in its source, type-only imports included
    (``from a import b`` counts as importing ``a.b`` when that is a module)."""
    is_pkg = path.name == "__init__.py"
    found: set[str] = set()
    tree = ast.parse(path.read_text(), str(path))
    for node in ast.walk(tree):  # ``if TYPE_CHECKING:`` imports count too: an annotation is a dependency
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = name.split(".")[: len(name.split(".")) - node.level + (1 if is_pkg else 0)]
                base = ".".join(up + ([node.module] if node.module else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
        else:
            continue
        found |= {t for t in targets if t.split(".")[0] == package and t != name}
    return found


def layer_of(module: str) -> int:
    parts = module.split(".")[1:]
    return next(RANK[".".join(parts[:n])] for n in range(len(parts), -1, -1) if ".".join(parts[:n]) in RANK)


def import_graph() -> dict[str, set[str]]:
    modules = all_modules()
    return {name: imports_of(name, path, modules) for name, path in modules.items()}


def test_every_module_has_a_layer():
    unknown = sorted({m.split(".")[1] for m in all_modules() if "." in m} - set(RANK))
    assert not unknown, f"add these to LAYERS: {unknown}"


def test_each_package_sits_on_one_floor():
    split = sorted({name.split(".")[0] for names in LAYERS for name in names if "." in name} - SPLIT_PACKAGES)
    assert not split, f"packages split across floors (move the lower part into a lower package): {split}"


def test_imports_only_go_down():
    graph = import_graph()
    upward = sorted((a, b) for a, bs in graph.items() for b in bs
                    if layer_of(b) > layer_of(a) and (a, b) not in ALLOWED_UPWARD)
    lines = "\n".join(f"  {a} -> {b}  (layer {layer_of(a)} -> {layer_of(b)})" for a, b in upward)
    print(lines)
    assert not upward, f"imports that go up a layer:\n{lines}"


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
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
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles():
    graph = {a: {b for b in bs if (a, b) not in ALLOWED_UPWARD} for a, bs in import_graph().items()}
    cycles = _cycles(graph)
    lines = "\n".join(f"  {' <-> '.join(c)}: " + ", ".join(f"{a} -> {b}" for a in c for b in sorted(graph[a]) if b in c)
                      for c in cycles)
    print(lines)
    assert not cycles, f"import cycles:\n{lines}"


def test_the_checker_sees_function_level_imports(tmp_path):
    src = tmp_path / "m.py"
    src.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from nerf2gs_plugin.viewer import server\n"
                   "def f():\n    from nerf2gs_plugin.eval import metrics\n    import nerf2gs_plugin.cli.train\n")
    found = imports_of("nerf2gs_plugin.data.m", src, {"nerf2gs_plugin.eval.metrics": src, "nerf2gs_plugin.viewer.server": src})
    assert found == {"nerf2gs_plugin.eval.metrics", "nerf2gs_plugin.cli.train", "nerf2gs_plugin.viewer.server"}
    assert layer_of("nerf2gs_plugin.masking.make_masks") > layer_of("nerf2gs_plugin.methods.x") > layer_of("nerf2gs_plugin.masks.auto")
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


BENCH = "nerf2gs_bench"


def test_the_package_never_imports_the_bench():
    """``nerf2gs_bench`` (``ns2gs-bench``, its benches, the validation plans) sits above every layer: the
    product never imports it, not even for a type annotation."""
    modules = all_modules()
    found = sorted(f"{a} -> {b}" for a, path in modules.items() for b in imports_of(a, path, modules, package=BENCH))
    assert not found, "the package imports the bench:\n  " + "\n  ".join(found)
