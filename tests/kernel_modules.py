"""Print a `--cov=MODULE` argument for every module of the package that declares a numba kernel (an `@njit`
decorator), for `make test-nojit`: its coverage threshold is over the kernel modules, not the Python around them.
Run from the repository's root."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
KERNEL = re.compile(r"^@(?:numba\.)?njit\b", re.M)


def kernel_modules() -> list[str]:
    """Dotted names of the package's modules with at least one `@njit` kernel, sorted."""
    found = []
    for path in sorted((ROOT / "datmo_cli").rglob("*.py")):
        if KERNEL.search(path.read_text(encoding="utf-8")):
            found.append(".".join(path.relative_to(ROOT).with_suffix("").parts))
    return found


if __name__ == "__main__":
    print(" ".join(f"--cov={m}" for m in kernel_modules()))
