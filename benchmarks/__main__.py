"""Run every benchmarks/bench_*.py (make bench) or accuracy_*.py (make accuracy) module's main()."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path


def main() -> int:
    prefix = sys.argv[1] if len(sys.argv) > 1 else "bench"
    only = sys.argv[2:]
    here = Path(__file__).parent
    failed = 0
    for path in sorted(here.glob(f"{prefix}_*.py")):
        if only and not any(o in path.stem for o in only):
            continue
        module = importlib.import_module(f"benchmarks.{path.stem}")
        try:
            module.main()
        except Exception as exc:  # report and go on with the other benchmarks
            print(f"{path.name}: FAILED: {exc!r}")
            failed += 1
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
