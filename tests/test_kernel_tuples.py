"""Kernels name what they take (CONTRIBUTING.md, "Add or change a kernel"): no @njit function unpacks more than
six values by position, neither a tuple (`a, b, c, d, e, f, g = work`) nor its items (`work[0], work[1], ...`).
Scratch, setup and measurement bundles travel as named tuples read by field, so two arrays of one dtype swapped
cannot compile and run wrong."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parent.parent / "datmo_cli"
MOST = 6

# sites still unpacking by position, "module:function", each removed by the change that names its values
KNOWN: set[str] = set()


def _is_kernel(fn: ast.FunctionDef) -> bool:
    return any("njit" in ast.unparse(d) for d in fn.decorator_list)


def _positional_width(target: ast.expr) -> int:
    """How many values an assignment target takes by position (0: not a tuple target)."""
    return len(target.elts) if isinstance(target, ast.Tuple | ast.List) else 0


def _indexed_width(value: ast.expr) -> int:
    """How many items of one name a tuple expression takes by constant index (`w[0], w[1], ...`)."""
    if not isinstance(value, ast.Tuple):
        return 0
    counts: dict[str, int] = {}
    for elt in value.elts:
        if (
            isinstance(elt, ast.Subscript)
            and isinstance(elt.value, ast.Name)
            and isinstance(elt.slice, ast.Constant)
            and isinstance(elt.slice.value, int)
        ):
            counts[elt.value.id] = counts.get(elt.value.id, 0) + 1
    return max(counts.values(), default=0)


def positional_sites() -> dict[str, int]:
    """'module:function' -> the widest positional unpacking in that kernel, for kernels over MOST."""
    sites: dict[str, int] = {}
    for path in sorted(ROOT.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for fn in ast.walk(tree):
            if not (isinstance(fn, ast.FunctionDef) and _is_kernel(fn)):
                continue
            widest = 0
            for node in ast.walk(fn):
                if isinstance(node, ast.Assign):
                    for target in node.targets:
                        widest = max(widest, _positional_width(target))
                    widest = max(widest, _indexed_width(node.value))
                elif isinstance(node, ast.For):
                    widest = max(widest, _positional_width(node.target))
            if widest > MOST:
                sites[f"{path.relative_to(ROOT).as_posix()}:{fn.name}"] = widest
    return sites


def test_the_check_sees_a_wide_unpacking():
    src = (
        "@njit(cache=True)\ndef k(w):\n    a, b, c, d, e, f, g = w\n"
        "    return w[0], w[1], w[2], w[3], w[4], w[5], w[6]\n"
    )
    fn = ast.parse(src).body[0]
    assert isinstance(fn, ast.FunctionDef) and _is_kernel(fn)
    assign, ret = fn.body
    assert _positional_width(assign.targets[0]) == 7
    assert _indexed_width(ret.value) == 7


def test_no_kernel_unpacks_more_than_six_values_by_position():
    sites = positional_sites()
    new = {site: n for site, n in sites.items() if site not in KNOWN}
    assert not new, f"kernels unpacking more than {MOST} values by position (use a named tuple): {new}"


def test_known_sites_still_exist():
    gone = KNOWN - set(positional_sites())
    assert not gone, f"remove from KNOWN, they name their values now: {sorted(gone)}"
