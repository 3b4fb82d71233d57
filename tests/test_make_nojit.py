"""`make test-nojit` measures the coverage of the kernel modules (every module with an @njit kernel, found by
tests/kernel_modules.py) and fails under KERNEL_COVERAGE, at least 80 %."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.kernel_modules import kernel_modules

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parent.parent


def test_kernel_modules_are_the_njit_modules():
    found = kernel_modules()
    assert "datmo_cli.tracking._step" in found and "datmo_cli.perception.segmentation" in found
    assert "datmo_cli.base.numba_runtime" not in found  # it patches numba, it declares no kernel
    for name in found:
        text = (ROOT / Path(*name.split("."))).with_suffix(".py").read_text(encoding="utf-8")
        assert re.search(r"^@(?:numba\.)?njit\b", text, re.M), name


def test_nojit_target_fails_under_the_threshold():
    make = (ROOT / "Makefile").read_text()
    threshold = re.search(r"^KERNEL_COVERAGE = (\d+)", make, re.M)
    assert threshold and int(threshold.group(1)) >= 80
    target = re.search(r"^test-nojit:.*\n((?:\t.*\n)+)", make, re.M)
    assert target is not None
    recipe = target.group(1)
    assert "tests/kernel_modules.py" in recipe and "--cov-fail-under=$(KERNEL_COVERAGE)" in recipe


def test_kernel_modules_prints_cov_arguments():
    out = subprocess.run([sys.executable, "tests/kernel_modules.py"], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0
    args = out.stdout.split()
    assert args == [f"--cov={m}" for m in kernel_modules()]
