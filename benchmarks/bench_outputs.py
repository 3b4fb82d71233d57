"""Output size and time order of `datmo run` on non-repeating logs: the simulated hall (benchmarks.hall_log) and
CARMEN intel (imported with `datmo import`, when ../shared/data is there).

Prints, per log, the output's size against its input (default and --markers) beside the targets, the largest
gap by which a message comes after a later one when the output is read from start to end without its index
(target: under streaming.CHUNK_SECONDS), and what that bound costs: the default output against the same
messages chunked by channel without windows (target: at most +5 %).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks.common import print_lines
from benchmarks.hall_log import CACHE, simulated_hall

ROOT = Path(__file__).resolve().parent.parent
INTEL = ROOT.parent / "shared" / "data" / "carmen" / "intel-corrected.log.gz"
TARGETS = {"hall": 1.3, "intel": 2.5}  # default output / input (issue 34, must-hold 4)
MARKERS_TARGET = 2.5  # --markers output / input (docs/performance.md)
GROWTH_TARGET = 0.05  # what the time-order bound may add (issue 37, must-hold 2)


def intel_log() -> Path | None:
    """CARMEN intel as `datmo import` writes it, made once into the bench cache; None without ../shared/data."""
    if not INTEL.exists():
        return None
    path = CACHE / "intel.mcap"
    if not path.exists():
        CACHE.mkdir(parents=True, exist_ok=True)
        cmd = [sys.executable, "-m", "datmo_cli", "import", str(INTEL), "-o", str(path), "--force"]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return path


def file_order_gap(path: Path) -> float:
    """The most log time (s) by which a message comes after a later one, reading `path` from start to end
    without its summary (mcap's StreamReader, as a pipe or a cut download reads it)."""
    from mcap.records import Message
    from mcap.stream_reader import StreamReader

    latest, worst = None, 0
    with open(path, "rb") as f:
        for record in StreamReader(f).records:
            if isinstance(record, Message):
                latest = record.log_time if latest is None else max(latest, record.log_time)
                worst = max(worst, latest - record.log_time)
    return worst / 1e9


def run_output(src: Path, out: Path, *, markers: bool = False, unbounded: bool = False) -> Path:
    """`datmo run`'s output of `src` (default options, or --markers); `unbounded`: chunked by channel without
    the windows of log time (how the size is compared)."""
    from datmo_cli.passes import streaming
    from datmo_cli.passes.pipeline import process_file

    seconds = streaming.CHUNK_SECONDS
    streaming.CHUNK_SECONDS = 0.0 if unbounded else seconds
    try:
        process_file(src, out, force=True, markers=markers)
    finally:
        streaming.CHUNK_SECONDS = seconds
    return out


def measure(name: str, src: Path, tmp: Path) -> list[str]:
    size = src.stat().st_size
    default = run_output(src, tmp / f"{name}.mcap")
    marked = run_output(src, tmp / f"{name}-markers.mcap", markers=True)
    loose = run_output(src, tmp / f"{name}-unbounded.mcap", unbounded=True)
    ratio, ratio_m = default.stat().st_size / size, marked.stat().st_size / size
    growth = default.stat().st_size / loose.stat().st_size - 1
    gap, gap_m = file_order_gap(default), file_order_gap(marked)
    target = TARGETS[name]
    return [
        f"{name}: input {size / 1e6:.2f} MB; default output {default.stat().st_size / 1e6:.2f} MB = {ratio:.2f}x its "
        f"input (target <= {target}x: {'met' if ratio <= target else 'NOT met'}); --markers "
        f"{marked.stat().st_size / 1e6:.2f} MB = {ratio_m:.2f}x (target <= {MARKERS_TARGET}x: "
        f"{'met' if ratio_m <= MARKERS_TARGET else 'NOT met'})",
        f"{name}: largest gap in file order (no index) {gap:.2f} s, --markers {gap_m:.2f} s (target < 5 s); the "
        f"bound costs {100 * growth:+.1f} % against chunks by channel without it (target <= "
        f"{100 * GROWTH_TARGET:.0f} %)",
    ]


def main() -> None:
    logs = {"hall": simulated_hall(), "intel": intel_log()}
    lines = []
    with tempfile.TemporaryDirectory() as folder:
        for name, src in logs.items():
            if src is None:
                lines.append(f"{name}: skipped ({INTEL} is absent)")
                continue
            lines += measure(name, src, Path(folder))
    print_lines("Output size and time order (datmo run, non-repeating logs)", lines)


if __name__ == "__main__":
    main()
