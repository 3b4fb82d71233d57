"""The package's layers are its folders (docs/architecture.md), and its imports read one way: every import of
every module under datmo_cli, at the top or inside a function, points down the layers or within its own layer,
and no modules import each other in a circle (not even within a layer, nor through a function-level import).

    cli        commands/ (one module a command), beside the package's doors cli.py and __main__.py: Click only
    pipeline   passes/ (the stages, the passes over a log and the configuration tree), batch/, report/, evaluate/,
               export/, live/, tune/, workflows/, ros2/, beside the Python door api.py
    core       perception/, tracking/, sim/, lms2xx/ (each importing only itself, logs and base), above logs
    log        logs/ (reading and writing logs; importing only itself and base)
    base       base/ (errors, safe inputs and outputs, bounds, progress, text, numba's set-up) and the package
               itself (__version__): usable by every layer, importing only base

Every module lives in one of these folders, but the doors. Only the CLI layer imports click (at the top or inside
a function): the layers below it take plain values, and what a command shares with them (--quiet, ./datmo.toml
picked up) reaches them through progress.command_meta, which the CLI layer points at Click's context.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

PACKAGE = "datmo_cli"
ROOT = Path(__file__).resolve().parent.parent / PACKAGE

FOLDERS = {
    "base": {"base"},
    "log": {"logs"},
    "core": {"perception", "tracking", "sim", "lms2xx"},
    "pipeline": {"passes", "batch", "report", "evaluate", "export", "live", "tune", "workflows", "ros2"},
    "cli": {"commands"},
}
# the modules beside the folders: the package itself, the command (cli, __main__) and the Python API
DOORS = {"": "base", "__main__": "cli", "cli": "cli", "api": "pipeline"}
CORE = FOLDERS["core"]
RANK = {"base": 0, "log": 1, "core": 2, "pipeline": 3, "cli": 4}
FOLDER_LAYER = {folder: name for name, folders in FOLDERS.items() for folder in folders}

# arrows against the layers that another branch removes; each names that branch
KNOWN: set[tuple[str, str]] = set()
# import circles (the modules of each) that another branch removes; each names that branch
KNOWN_CIRCLES: set[frozenset[str]] = set()


def layer(module: str) -> tuple[str, str]:
    """(layer, unit) of a module name: the unit is the core package a core module belongs to (modules of one
    core package may import each other, not another's), else the layer itself. A module outside the layer
    folders and doors is in no layer ("unplaced")."""
    parts = module.split(".")
    top = parts[1] if len(parts) > 1 else ""
    if top in DOORS:
        return DOORS[top], DOORS[top]
    if top not in FOLDER_LAYER:
        return "unplaced", top
    name = FOLDER_LAYER[top]
    return name, top if name == "core" else name


def rule_broken(src: str, dst: str) -> str | None:
    """Why `src` may not import `dst` (None: it may)."""
    (ls, us), (ld, ud) = layer(src), layer(dst)
    if "unplaced" in (ls, ld):
        return f"{us if ls == 'unplaced' else ud} is in no layer folder"
    if RANK[ld] > RANK[ls]:
        return f"{ls} may not import {ld} (a layer above it)"
    if ls == "core" and ld == "core" and us != ud:
        return f"core package {us} may not import core package {ud} (sideways)"
    return None


def test_every_module_lives_in_a_layer_folder():
    """The folders are the layers: no module lies loose in the package root but its doors, and no folder is in
    no layer (a new folder is given its layer in FOLDERS)."""
    loose = sorted(p.stem for p in ROOT.glob("*.py") if p.stem not in DOORS and p.stem != "__init__")
    folders = {p.name for p in ROOT.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert not loose, f"modules outside the layer folders: {loose}"
    assert folders == set(FOLDER_LAYER), (folders - set(FOLDER_LAYER), set(FOLDER_LAYER) - folders)


def module_name(path: Path, root: Path) -> str:
    parts = [root.name, *path.relative_to(root).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path, root: Path, modules: set[str]) -> list[tuple[str, int]]:
    """(module imported, line) of every import of `path` (at any depth) inside the package: `from X import Y`
    counts as an import of X.Y when that is a module, else of X."""
    name = module_name(path, root)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names if a.name.split(".")[0] == root.name]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != root.name:
                continue
            for a in node.names:
                sub = f"{target}.{a.name}"
                out.append((sub if sub in modules else target, node.lineno))
    return list(dict.fromkeys(out))  # one per module imported and line


def arrows(root: Path = ROOT) -> list[tuple[str, int, str, str]]:
    """(module, line, module imported, rule broken) of every import under `root` (a package folder) against
    the layers."""
    files = sorted(root.rglob("*.py"))
    modules = {module_name(p, root) for p in files}
    out = []
    for p in files:
        src = module_name(p, root)
        for dst, line in imports(p, root, modules):
            why = rule_broken(src, dst)
            if why is not None:
                out.append((src, line, dst, why))
    return out


def violations(root: Path = ROOT, known: set = frozenset()) -> list[str]:
    """The arrows under `root` against the layers but the `known` (module, module imported) pairs, as
    "module:line imports target: rule"."""
    return [f"{src}:{line} imports {dst}: {why}" for src, line, dst, why in arrows(root) if (src, dst) not in known]


def import_graph(root: Path = ROOT) -> dict[str, dict[str, int]]:
    """{module: {module it imports: line of the first such import}} of every module under `root` (a package
    folder), top-level and function-level imports alike."""
    files = sorted(root.rglob("*.py"))
    modules = {module_name(p, root) for p in files}
    out: dict[str, dict[str, int]] = {}
    for p in files:
        src = module_name(p, root)
        out[src] = {}
        for dst, line in imports(p, root, modules):
            if dst in modules and dst != src:
                out[src].setdefault(dst, line)
    return out


def circles(root: Path = ROOT) -> list[frozenset[str]]:
    """The import circles under `root`: each set of two or more modules that reach one another through imports
    (a strongly connected component of import_graph, Tarjan's algorithm)."""
    graph = import_graph(root)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = stack[stack.index(v) :]
            del stack[stack.index(v) :]
            if len(group) > 1:
                out.append(frozenset(group))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def describe_circle(group: frozenset[str], root: Path = ROOT) -> str:
    """The imports between the modules of an import circle, "a:line imports b", one a line."""
    graph = import_graph(root)
    return "\n".join(f"  {a}:{line} imports {b}" for a in sorted(group) for b, line in graph[a].items() if b in group)


def test_no_import_circle():
    bad = [g for g in circles(ROOT) if g not in KNOWN_CIRCLES]
    assert not bad, "import circles:\n" + "\n".join(describe_circle(g) for g in bad)


def test_the_known_circles_are_still_there():
    """A known circle that is gone (or has changed) is deleted from KNOWN_CIRCLES (so none outlives its fix)."""
    assert KNOWN_CIRCLES <= set(circles(ROOT)), KNOWN_CIRCLES - set(circles(ROOT))


def test_a_planted_import_circle_is_reported(tmp_path):
    root = tmp_path / PACKAGE
    (root / "perception").mkdir(parents=True)
    for name in ("__init__.py", "perception/__init__.py", "perception/b.py"):
        (root / name).write_text("")
    (root / "perception/features.py").write_text("from .b import x\n")
    (root / "perception/markers.py").write_text("from . import features\n")
    assert circles(root) == []
    (root / "perception/b.py").write_text("def f():\n    from .markers import y\n")
    assert circles(root) == [frozenset({f"{PACKAGE}.perception.{m}" for m in ("features", "markers", "b")})]
    assert f"{PACKAGE}.perception.b:2 imports {PACKAGE}.perception.markers" in describe_circle(circles(root)[0], root)


def test_the_package_imports_read_one_way():
    bad = violations(ROOT, KNOWN)
    assert not bad, "imports against the layers:\n" + "\n".join(bad)


def click_imports(root: Path = ROOT) -> list[str]:
    """ "module:line" of every import of click (or a click submodule) under `root` outside the CLI layer."""
    files = sorted(root.rglob("*.py"))
    out = []
    for p in files:
        name = module_name(p, root)
        if layer(name)[0] == "cli":
            continue
        for node in ast.walk(ast.parse(p.read_text(), str(p))):
            if isinstance(node, ast.Import):
                hit = any(a.name.split(".")[0] == "click" for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                hit = node.level == 0 and (node.module or "").split(".")[0] == "click"
            else:
                continue
            if hit:
                out.append(f"{name}:{node.lineno}")
    return out


def test_only_the_cli_layer_imports_click():
    bad = click_imports(ROOT)
    assert not bad, "click imported below the CLI layer:\n" + "\n".join(bad)


@pytest.mark.parametrize(
    "where, code, reported",
    [
        ("base/progress.py", "import click\n", True),
        ("passes/config.py", "def f():\n    from click import echo\n", True),
        ("logs/bad.py", "def f():\n    import click.testing\n", True),
        ("commands/run.py", "import click\n", False),
        ("cli.py", "def f():\n    import click\n", False),
        ("base/bounds.py", "from .click import x\n", False),
    ],
)
def test_a_planted_click_import_is_reported_below_the_cli_layer(tmp_path, where, code, reported):
    root = tmp_path / PACKAGE
    for folder in ("", "base", "passes", "logs", "commands"):
        (root / folder).mkdir(exist_ok=True)
        (root / folder / "__init__.py").write_text("")
    (root / where).write_text(code)
    assert bool(click_imports(root)) == reported, click_imports(root)


def test_the_known_exceptions_are_still_needed():
    """An exception whose arrow is gone is deleted from KNOWN (so none outlives its fix)."""
    assert KNOWN <= {(src, dst) for src, _, dst, _ in arrows(ROOT)}, KNOWN - {(s, d) for s, _, d, _ in arrows()}


@pytest.mark.parametrize(
    "where, code, rule",
    [
        ("logs/bad.py", "from ..cli import invocation\n", "log may not import cli"),
        ("tracking/bad.py", "def f():\n    from datmo_cli.perception import features\n", "sideways"),
        ("perception/bad.py", "import datmo_cli.sim.simulate\n", "sideways"),
        ("base/progress.py", "def f():\n    from ..commands import compiling\n", "base may not import cli"),
        ("sim/bad.py", "from ..passes import pipeline\n", "core may not import pipeline"),
        ("passes/bad.py", "from ..loose import x\n", "loose is in no layer folder"),
    ],
)
def test_a_planted_bad_import_is_reported(tmp_path, where, code, rule):
    root = tmp_path / PACKAGE
    for folder in ("", "base", "passes", "logs", "tracking", "perception", "sim", "commands"):
        (root / folder).mkdir(exist_ok=True)
        (root / folder / "__init__.py").write_text("")
    for name in (
        "cli.py",
        "loose.py",
        "passes/pipeline.py",
        "commands/compiling.py",
        "perception/features.py",
        "sim/simulate.py",
    ):
        (root / name).write_text("")
    (root / where).write_text(code)
    bad = violations(root)
    assert len(bad) == 1 and bad[0].startswith(module_name(root / where, root) + ":") and rule in bad[0], bad


def test_imports_down_and_within_a_layer_pass(tmp_path):
    root = tmp_path / PACKAGE
    for folder in ("logs", "tracking", "base", "passes"):
        (root / folder).mkdir(parents=True)
        (root / folder / "__init__.py").write_text("")
    for name in ("__init__.py", "base/errors.py", "logs/scan.py"):
        (root / name).write_text("")
    (root / "tracking/kalman.py").write_text(
        "from ..logs import scan\nfrom ..base.errors import InputError\n"
        "from . import kalman\nfrom datmo_cli import __version__\n"
    )
    (root / "passes/stages.py").write_text("from ..tracking import kalman\nfrom ..base import errors\n")
    (root / "cli.py").write_text("def main():\n    from .passes import stages\n")
    assert violations(root) == []


MOST_LINES = 500  # a module a reader can hold: split it by what it holds beyond this
THIN_COMMANDS = {"run": 150, "record": 150}  # the commands that once held their own orchestration


def long_modules(root: Path = ROOT) -> dict[str, int]:
    """{module path: lines} of the modules under `root` over MOST_LINES."""
    sizes = {
        p.relative_to(root).as_posix(): len(p.read_text(encoding="utf-8").splitlines()) for p in root.rglob("*.py")
    }
    return {path: n for path, n in sorted(sizes.items()) if n > MOST_LINES}


def test_no_module_is_over_500_lines():
    assert not long_modules(), f"modules over {MOST_LINES} lines: {long_modules()}"


def test_a_planted_long_module_is_reported(tmp_path):
    (tmp_path / "ok.py").write_text("x = 1\n" * MOST_LINES)
    (tmp_path / "long.py").write_text("x = 1\n" * (MOST_LINES + 1))
    assert long_modules(tmp_path) == {"long.py": MOST_LINES + 1}


@pytest.mark.parametrize("command, most", sorted(THIN_COMMANDS.items()))
def test_the_commands_stay_thin(command, most):
    """options, one call of datmo_cli.api, what it prints: the work itself is in the pipeline layer."""
    lines = len((ROOT / "commands" / f"{command}.py").read_text(encoding="utf-8").splitlines())
    assert lines < most, f"commands/{command}.py: {lines} lines"
