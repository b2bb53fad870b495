"""The import structure: data flows one way, content -> pipeline -> bundle -> runtime -> pixels.

Every module under ``src/piste`` is parsed with :mod:`ast` (nothing is imported), and its imports
(top-level *and* inside functions) become edges of a module graph.  The rules (ARCHITECTURE.md):

* ``formats`` imports nothing from ``terrain``, ``world``, ``pipeline``, ``render``, ``lighting`` or
  ``commands``;
* ``character`` imports nothing from ``formats``, ``terrain`` or ``lighting`` either;
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
    "formats": ("terrain", "world", "pipeline", "render", "lighting", "commands"),
    "terrain": ("world", "pipeline", "render", "commands"),
    "character": ("formats", "terrain", "lighting", "world", "pipeline", "render", "commands"),
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
COMMAND_IMPORTS_LEFT: set = set()


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


# ----------------------------------------------------------------------------- every layer, written out
#: the foundation (ARCHITECTURE.md's first row): imports nothing of piste's but itself
FOUNDATION = ("errors", "extras", "transforms", "scene_data", "workers", "graph", "_jit", "_data")
_ABOVE_FOUNDATION = ("formats", "terrain", "character", "lighting", "world", "render", "pipeline", "commands", "cli")
FORBIDDEN.update({name: _ABOVE_FOUNDATION for name in FOUNDATION})
FORBIDDEN.update({
    "world": ("pipeline", "render", "commands", "cli"),
    "render": ("pipeline", "commands", "cli"),
    "pipeline": ("commands", "cli"),
})
for _layer_name in ("formats", "terrain", "character", "lighting"):
    FORBIDDEN[_layer_name] = tuple(dict.fromkeys(FORBIDDEN[_layer_name] + ("cli",)))


def test_every_layer_has_its_rule():
    """Each subpackage and top-level module is a layer with a rule (only ``commands``/``cli`` at the
    top may import everything), so a new package cannot slip in unchecked."""
    modules, _, _ = import_graph()
    layers = {_layer(m) for m in modules} - {""}
    assert layers - set(FORBIDDEN) == {"commands", "cli"}, sorted(layers - set(FORBIDDEN))


# ----------------------------------------------------------------------------- private writes, environment
#: modules that may read the environment (ARCHITECTURE.md: options reach the cores as parameters)
ENV_OK = ("piste.cli", "piste.extras")

#: breaches still to remove, each with who removes it: (module, field or "environ")
KNOWN_LEFT: set = set()


def _known(line: str) -> bool:
    module = line.split(" (")[0]
    return any(module == m and (f"._{f[1:]}" in line or f in line) for m, f in KNOWN_LEFT)


def _trees():
    modules, _, _ = import_graph()
    for name, path in modules.items():
        yield name, ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def _targets(node):
    if isinstance(node, ast.Assign):
        todo = list(node.targets)
    elif isinstance(node, (ast.AugAssign, ast.AnnAssign)):
        todo = [node.target]
    elif isinstance(node, ast.Delete):
        todo = list(node.targets)
    else:
        return
    while todo:
        t = todo.pop()
        if isinstance(t, (ast.Tuple, ast.List)):
            todo.extend(t.elts)
        elif isinstance(t, ast.Starred):
            todo.append(t.value)
        else:
            yield t


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _own_fields(tree) -> set[str]:
    """Private fields a module defines: assigned on ``self``/``cls`` or declared in a class body."""
    own = set()
    for node in ast.walk(tree):
        for t in _targets(node):
            if isinstance(t, ast.Attribute) and isinstance(t.value, ast.Name) and t.value.id in ("self", "cls"):
                own.add(t.attr)
        if isinstance(node, ast.ClassDef):
            for item in node.body:
                for t in _targets(item):
                    if isinstance(t, ast.Name):
                        own.add(t.id)
    return own


def private_writes(trees) -> list[str]:
    """``obj._x = ...`` (also ``+=``, ``del``, ``setattr(obj, "_x", ...)``) where ``obj`` is not
    ``self``/``cls`` and ``_x`` is not a field the writing module itself defines (an alternative
    constructor filling its own class's fields is fine): one module writing another's private field."""
    bad = []
    for name, tree in trees:
        own = _own_fields(tree)
        for node in ast.walk(tree):
            for t in _targets(node):
                if (isinstance(t, ast.Attribute) and _private(t.attr) and t.attr not in own
                        and not (isinstance(t.value, ast.Name) and t.value.id in ("self", "cls"))):
                    bad.append(f"{name} (line {t.lineno}): {' '.join(ast.unparse(node).split())[:120]}")
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in ("setattr", "delattr")
                    and len(node.args) >= 2 and isinstance(node.args[1], ast.Constant)
                    and isinstance(node.args[1].value, str) and _private(node.args[1].value)
                    and node.args[1].value not in own
                    and not (isinstance(node.args[0], ast.Name) and node.args[0].id in ("self", "cls"))):
                bad.append(f"{name} (line {node.lineno}): {ast.unparse(node)[:120]}")
    return sorted(bad, key=lambda b: (b.split(" (")[0], int(b.split("line ")[1].split(")")[0])))


def environment_reads(trees) -> list[str]:
    """``os.environ`` / ``os.getenv`` / ``os.putenv`` (or ``environ``/``getenv`` imported from os)
    outside :data:`ENV_OK`."""
    bad = []
    for name, tree in trees:
        if name in ENV_OK:
            continue
        aliases = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module == "os":
                aliases |= {a.asname or a.name for a in node.names if a.name in ("environ", "getenv", "putenv")}
        for node in ast.walk(tree):
            hit = (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "os"
                   and node.attr in ("environ", "getenv", "putenv", "unsetenv", "environb"))
            hit = hit or (isinstance(node, ast.Name) and node.id in aliases)
            if hit:
                bad.append(f"{name} (line {node.lineno}): {ast.unparse(node)}")
    return sorted(bad, key=lambda b: (b.split(" (")[0], int(b.split("line ")[1].split(")")[0])))


def test_no_module_writes_another_objects_private_fields():
    bad = [b for b in private_writes(_trees()) if not _known(b)]
    assert not bad, ("private attributes written from outside their object (add a public method or keyword "
                     "to the owner; ARCHITECTURE.md 'Public hooks, not private writes'):\n  " + "\n  ".join(bad))


def test_the_environment_is_read_only_by_the_cli_and_extras():
    bad = [b for b in environment_reads(_trees()) if not _known(b)]
    assert not bad, ("environment reads outside piste.cli / piste.extras (pass an option as a parameter, or list "
                     "the variable in piste.extras.ENVIRONMENT and read it with piste.extras.environ):\n  "
                     + "\n  ".join(bad))


def test_the_private_write_and_environment_checks_can_fail():
    src = (
        "import os\nfrom os import environ as env\n\n"
        "class A:\n    def f(self, other):\n        self._ok = 1\n        other._bad = 2\n"
        "        other._n += 1\n        setattr(other, '_also_bad', 3)\n        other.__dict__ = {}\n"
        "    @classmethod\n    def make(cls):\n        a = cls.__new__(cls)\n        a._ok = 1\n\n"
        "x = os.environ.get('HOME')\ny = env['HOME']\nz = os.getenv('HOME')\n"
    )
    trees = [("piste.pipeline.a", ast.parse(src)), ("piste.extras", ast.parse("import os\nos.environ['X']\n"))]
    assert [b.split(":")[0] for b in private_writes(trees)] == [
        "piste.pipeline.a (line 7)", "piste.pipeline.a (line 8)", "piste.pipeline.a (line 9)"]
    assert [b.split(":")[0] for b in environment_reads(trees)] == [
        "piste.pipeline.a (line 16)", "piste.pipeline.a (line 17)", "piste.pipeline.a (line 18)"]


# ----------------------------------------------------------------------------- formats <-> terrain
def test_formats_and_terrain_do_not_import_each_other():
    """One direction only: the cores read and write through ``formats`` (``PatchNet.from_bpt``, the
    tiles' safe I/O), so ``formats`` imports no terrain code: a conversion to or from a PatchNet
    lives above it (``pipeline.ssx_level.pbd_to_net``, ``pipeline.ssx_synth``,
    ``terrain.tessellate.terrain_mesh`` for the glTF writer)."""
    _, imports, _ = import_graph()
    up = sorted(i.where() for i in imports if i.module.startswith("piste.formats")
                and (i.target == "piste.terrain" or i.target.startswith("piste.terrain.")))
    down = {i.module for i in imports if i.module.startswith("piste.terrain") and i.target.startswith("piste.formats")}
    assert down, "the check is moot: terrain no longer reads through formats (turn the rule around)"
    assert not up, ("formats imports terrain while terrain imports formats (one direction must go):\n  "
                    + "\n  ".join(up))


# ----------------------------------------------------------------------------- the library prints nothing
#: modules that may print: the command line (its output is the user's), and what is left to move
PRINT_OK = ("piste.cli", "piste.commands")
PRINTS_LEFT: set = set()


def library_prints(trees) -> list[str]:
    """``print(...)`` calls outside the command line: the library reports through the ``piste``
    logger (``logging.getLogger(__name__)``; ``piste -v/-q`` sets its level), progress through tqdm."""
    bad = []
    for name, tree in trees:
        if name.startswith(PRINT_OK):
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print":
                bad.append(f"{name} (line {node.lineno}): {ast.unparse(node)[:100]}")
    return bad


def test_the_library_logs_instead_of_printing():
    bad = [b for b in library_prints(_trees()) if b.split(" (")[0] not in PRINTS_LEFT]
    assert not bad, "print() in library code (use logging.getLogger(__name__)):\n  " + "\n  ".join(bad)
    trees = [("piste.terrain.x", ast.parse("def f():\n    print('hi')\n")), ("piste.commands.y", ast.parse("print(1)\n"))]
    assert library_prints(trees) == ["piste.terrain.x (line 2): print('hi')"]
