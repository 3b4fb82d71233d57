"""datmo's outputs carry the same bits on every x86-64 CPU: Python-level code whose results reach an output calls
datmo_cli.base.libm (the C library's sin, cos, atan2), not numpy's float64 sin/cos/arctan2 and kin, whose SIMD loops
depend on the CPU (AVX-512 or not); numba kernels call the C library's functions everywhere."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from datmo_cli.base import libm

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parent.parent / "datmo_cli"
# numpy functions whose float64 loops numpy dispatches by CPU (SVML on AVX-512) and that are not exact
SIMD_MATH = {
    "sin",
    "cos",
    "tan",
    "arcsin",
    "arccos",
    "arctan",
    "arctan2",
    "sinh",
    "cosh",
    "tanh",
    "arcsinh",
    "arccosh",
    "arctanh",
    "exp",
    "exp2",
    "expm1",
    "log",
    "log2",
    "log10",
    "log1p",
    "power",
    "cbrt",
}
# modules whose results never reach a datmo output (plots, scoring against ground truth, the training tables)
NOT_OUTPUTS = ("evaluate/", "perception/training/", "report/")
KERNEL_DECORATORS = {"njit", "jit", "vectorize", "guvectorize", "stencil"}
# BLAS and LAPACK (numpy's and numba's both call them) choose their code, FMA or not, by the CPU: anywhere
BLAS = {"dot", "matmul", "inner", "vdot", "einsum", "tensordot", "linalg"}


def _decorated_as_kernel(fn: ast.FunctionDef) -> bool:
    for d in fn.decorator_list:
        node = d.func if isinstance(d, ast.Call) else d
        name = node.attr if isinstance(node, ast.Attribute) else getattr(node, "id", "")
        if name in KERNEL_DECORATORS:
            return True
    return False


def python_level_simd_math(path: Path, root: Path = ROOT) -> list[str]:
    """`np.<fn>(...)` calls of SIMD_MATH in `path` outside numba kernels, and BLAS anywhere: "file:line np.fn"."""
    tree = ast.parse(path.read_text())
    found: list[str] = []

    def visit(node: ast.AST, in_kernel: bool) -> None:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            in_kernel = in_kernel or (isinstance(node, ast.FunctionDef) and _decorated_as_kernel(node))
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.MatMult):
            found.append(f"{path.relative_to(root)}:{node.lineno} @")
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in {"np", "numpy"}
            and node.attr in BLAS
        ):
            found.append(f"{path.relative_to(root)}:{node.lineno} np.{node.attr}")
        if (
            not in_kernel
            and isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and isinstance(node.func.value, ast.Name)
            and node.func.value.id in {"np", "numpy"}
            and node.func.attr in SIMD_MATH
        ):
            found.append(f"{path.relative_to(root)}:{node.lineno} np.{node.func.attr}")
        for child in ast.iter_child_nodes(node):
            visit(child, in_kernel)

    visit(tree, False)
    return found


def test_no_cpu_dependent_math_reaches_an_output():
    found = []
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if not rel.startswith(NOT_OUTPUTS):
            found += python_level_simd_math(path)
    assert not found, "use datmo_cli.base.libm (same bits on every CPU) instead of: " + ", ".join(found)


def test_the_scan_finds_a_python_level_call_and_skips_kernels(tmp_path):
    src = tmp_path / "m.py"
    src.write_text(
        "import numpy as np\nfrom numba import njit\n\n@njit(cache=True)\ndef k(a):\n    return np.sin(a)\n\n"
        "def f(a):\n    return np.cos(a) + np.sqrt(a) + np.arctan2(a, a)\n\n"
        "@njit\ndef g(a):\n    return np.dot(a, a) + (a @ a)[0]\n"
    )
    found = python_level_simd_math(src, tmp_path)
    assert sorted(found) == sorted(["m.py:9 np.cos", "m.py:9 np.arctan2", "m.py:13 np.dot", "m.py:13 @"])


@pytest.mark.parametrize("fn", ["sin", "cos"])
def test_one_argument_functions_are_the_c_librarys(fn):
    x = np.random.default_rng(1).uniform(-50, 50, (7, 13))
    got = getattr(libm, fn)(x)
    assert got.shape == x.shape and got.dtype == np.float64
    assert got.ravel().tolist() == [getattr(math, fn)(v) for v in x.ravel().tolist()]
    assert getattr(libm, fn)(0.5) == getattr(math, fn)(0.5)
    assert getattr(libm, fn)(np.zeros(0)).shape == (0,)
    assert np.isnan(getattr(libm, fn)(np.array([np.inf, -np.inf, np.nan]))).all()
    np.testing.assert_allclose(got, getattr(np, fn)(x), rtol=0, atol=1e-15)


def test_arctan2_broadcasts_like_numpy_and_is_the_c_librarys():
    rng = np.random.default_rng(2)
    y, x = rng.normal(size=(4, 1)), rng.normal(size=(1, 5))
    got = libm.arctan2(y, x)
    want = np.array([[math.atan2(a, b) for b in x[0]] for a in y[:, 0]])
    assert got.shape == (4, 5) and got.tolist() == want.tolist()
    assert libm.arctan2(1.0, -1.0) == math.atan2(1.0, -1.0)
    np.testing.assert_allclose(got, np.arctan2(y, x), rtol=0, atol=1e-15)
