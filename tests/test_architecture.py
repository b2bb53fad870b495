"""The import structure: data flows one way, content -> pipeline -> bundle -> runtime -> pixels.

Every module under ``src/piste`` is parsed with :mod:`ast` (nothing is imported), and its imports
(top-level *and* inside functions) become edges of a module graph.  The rules (ARCHITECTURE.md):

* ``formats`` imports nothing from ``world``, ``pipeline``, ``render``, ``lighting`` or ``commands``;
* ``terrain``, ``character`` and ``lighting`` import nothing from ``world``, ``pipeline``,
  ``render`` or ``commands``;
* no import cycle between modules.  Importing ``piste.a.b`` first runs ``piste/a/__init__.py``, so
  an import of ``piste.a.b`` from outside package ``piste.a`` is also an edge to ``piste.a``;
* no function-level import of a piste module (a lazy import is how a cycle hides), except in
  ``piste.commands`` (the CLI loads a subcommand's modules only when it runs, so ``piste stats``
  never loads OpenGL).  Function-level imports of optional or heavy third-party packages
  (moderngl, pyglet, tqdm, scipy, ...) are fine.

Each failure names the module, the line and the import.
"""

from __future__ import annotations

import ast
import functools
from dataclasses import dataclass
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
ROOT = SRC / "piste"

#: package -> packages it must not import (the layers of ARCHITECTURE.md)
FORBIDDEN = {
    "formats": ("world", "pipeline", "render", "lighting", "commands"),
    "terrain": ("world", "pipeline", "render", "commands"),
    "character": ("world", "pipeline", "render", "commands"),
    "lighting": ("world", "pipeline", "render", "commands"),
}

#: subpackages whose functions may import piste modules lazily (CLI start-up time, not cycles)
LAZY_OK = ("piste.commands",)


@dataclass(frozen=True)
class Import:
    module: str  # the importing module, e.g. "piste.terrain.net"
    target: str  # the imported module, e.g. "piste.terrain.fit"
    line: int
    top_level: bool
    text: str  # the statement as written

    def where(self) -> str:
        return f"{self.module} (line {self.line}): {self.text}"


def module_name(path: Path) -> str:
    parts = path.relative_to(SRC).with_suffix("").parts
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def all_modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(ROOT.rglob("*.py"))}


def _is_top_level(node, parents) -> bool:
    """True for imports at module level (also inside a module-level ``if``/``try``)."""
    p = parents.get(node)
    while p is not None:
        if isinstance(p, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
            return False
        p = parents.get(p)
    return True


def imports_of(name: str, path: Path, modules: dict[str, Path]) -> list[Import]:
    """The piste imports of module ``name`` (relative imports resolved; ``from pkg import sub``
    resolves to the submodule when it is one)."""
    source = path.read_text(encoding="utf-8")
    tree = ast.parse(source, filename=str(path))
    parents = {}
    for node in ast.walk(tree):
        for child in ast.iter_child_nodes(node):
            parents[child] = node
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = []
            for a in node.names:
                sub = f"{mod}.{a.name}"
                targets.append(sub if sub in modules else mod)
        else:
            continue
        text = ast.unparse(node)
        top = _is_top_level(node, parents)
        for t in dict.fromkeys(targets):
            if t == "piste" or t.startswith("piste."):
                out.append(Import(name, t, node.lineno, top, " ".join(text.split())))
    return out


def import_graph():
    """``(modules, imports, edges)``: edges ``{module: {target: Import}}``, with the implicit edges to
    the packages a target lies in (their ``__init__`` runs first).  Parsed once per source tree."""
    return _import_graph(SRC, ROOT)


@functools.lru_cache(maxsize=4)
def _import_graph(src: Path, root: Path):
    modules = all_modules()
    imports = []
    for name, path in modules.items():
        imports += imports_of(name, path, modules)
    edges: dict[str, dict[str, Import]] = {m: {} for m in modules}
    for imp in imports:
        target = imp.target
        while target and target != "piste":
            if target in modules and target != imp.module and not imp.module.startswith(target + "."):
                edges[imp.module].setdefault(target, imp)
            target = target.rpartition(".")[0]
    return modules, imports, edges


def find_cycles(edges) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index, low, on, stack, out = {}, {}, set(), [], []
    counter = [0]
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges.get(w, ())))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
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
    return out


def _layer(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def test_every_module_parses_and_the_graph_is_not_empty():
    modules, imports, _ = import_graph()
    assert "piste.formats.bundle" in modules and "piste.terrain.net" in modules
    assert any(i.target.startswith("piste.terrain") for i in imports)


def test_lower_layers_do_not_import_upper_layers():
    _, imports, _ = import_graph()
    bad = []
    for imp in imports:
        layer = _layer(imp.module)
        for up in FORBIDDEN.get(layer, ()):
            if imp.target == f"piste.{up}" or imp.target.startswith(f"piste.{up}."):
                bad.append(f"{imp.where()}  -- piste.{layer} must not import piste.{up}")
    assert not bad, "imports that run back up the layers (see ARCHITECTURE.md):\n  " + "\n  ".join(bad)


def test_no_import_cycles():
    _, _, edges = import_graph()
    cycles = find_cycles(edges)
    lines = []
    for comp in cycles:
        lines.append("cycle between " + ", ".join(comp) + ":")
        members = set(comp)
        for m in comp:
            for target, imp in sorted(edges[m].items()):
                if target in members:
                    lines.append(f"    {imp.where()}  (-> {target})")
    assert not cycles, "import cycles (move the shared piece into its own module):\n" + "\n".join(lines)


def test_no_function_level_imports_of_piste_modules():
    _, imports, _ = import_graph()
    bad = [imp.where() for imp in imports if not imp.top_level and not imp.module.startswith(LAZY_OK)]
    assert not bad, ("function-level imports of piste modules (hoist them to the top of the module; if that makes "
                     "a cycle, the layering is wrong):\n  " + "\n  ".join(bad))


def test_the_checker_sees_a_cycle_and_a_layer_breach(tmp_path, monkeypatch):
    """The checks above can fail: a planted cycle and an upward import are reported by name."""
    pkg = tmp_path / "piste"
    (pkg / "formats").mkdir(parents=True)
    (pkg / "world").mkdir()
    for p in (pkg, pkg / "formats", pkg / "world"):
        (p / "__init__.py").write_text("")
    (pkg / "formats" / "a.py").write_text("from piste.world.b import x\n")
    (pkg / "world" / "b.py").write_text("def f():\n    from piste.formats import a\n")
    monkeypatch.setitem(globals(), "SRC", tmp_path)
    monkeypatch.setitem(globals(), "ROOT", pkg)
    _, imports, edges = import_graph()
    assert find_cycles(edges) == [["piste.formats.a", "piste.world.b"]]
    assert [i.where() for i in imports if not i.top_level] == ["piste.world.b (line 2): from piste.formats import a"]
    try:
        test_lower_layers_do_not_import_upper_layers()
    except AssertionError as exc:
        assert "piste.formats.a (line 1): from piste.world.b import x" in str(exc)
    else:
        raise AssertionError("the layer check missed formats -> world")


#: imports between command modules still to remove, each with who removes it (issue 25 item 2)
COMMAND_IMPORTS_LEFT = {
    ("piste.commands.ssx", "piste.commands.export"),  # export_bundle: moves with glTF into one subpackage
}


def command_imports(imports) -> list[Import]:
    """Imports of one ``piste.commands`` module by another: commands only parse and call the
    pipeline/runtime (shared parsing helpers are private modules, ``piste.commands._numbers``)."""
    out = []
    for imp in imports:
        if not imp.module.startswith("piste.commands.") or not imp.target.startswith("piste.commands."):
            continue
        if imp.target.rpartition(".")[2].startswith("_") or imp.target == imp.module:
            continue
        out.append(imp)
    return out


def test_commands_do_not_import_each_other():
    _, imports, _ = import_graph()
    bad = [f"{imp.where()}  -- move the shared work into the pipeline" for imp in command_imports(imports)
           if (imp.module, imp.target) not in COMMAND_IMPORTS_LEFT]
    assert not bad, "a command imports another command:\n  " + "\n  ".join(bad)


def test_the_command_check_sees_one_command_importing_another(tmp_path, monkeypatch):
    pkg = tmp_path / "piste"
    (pkg / "commands").mkdir(parents=True)
    for p in (pkg, pkg / "commands"):
        (p / "__init__.py").write_text("")
    (pkg / "commands" / "_numbers.py").write_text("SIZE = int\n")
    (pkg / "commands" / "demo.py").write_text("def f():\n    from piste.commands import _numbers\n")
    (pkg / "commands" / "view.py").write_text("def add_arguments(p):\n    from piste.commands.demo import f\n")
    monkeypatch.setitem(globals(), "SRC", tmp_path)
    monkeypatch.setitem(globals(), "ROOT", pkg)
    _, imports, _ = import_graph()
    assert [i.where() for i in command_imports(imports)] == [
        "piste.commands.view (line 2): from piste.commands.demo import f"]
