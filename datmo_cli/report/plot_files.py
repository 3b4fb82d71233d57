"""Where the plots of `datmo report --plot` and `datmo run --plot` go and how they are written: one path per
file (`plot_paths`), the checks made before any work (`check_plot_outputs`) and the atomic write of a drawn
run (`save_plot`, plot.plot_run)."""

from __future__ import annotations

from pathlib import Path

PLOT_SUFFIXES = (".png", ".svg", ".pdf")


def plot_paths(plot: Path, files: list[Path]) -> list[Path]:
    """Where each file's plot goes: `plot` itself for one file, else PLOT-STEM.SUFFIX per file; files of one
    stem in different folders get their folders' names too (A/x.mcap, B/x.mcap: PLOT-A-x.png, PLOT-B-x.png), so
    no plot is written over another (paths that are still one name once joined get -2, -3: _numbered). One
    file given twice is an InputError."""
    if len(files) == 1:
        return [plot]
    import os

    parts = [Path(os.path.abspath(f)).with_suffix("").parts[1:] for f in files]
    depth = [1] * len(files)
    while True:
        names = ["-".join(p[-d:]) for p, d in zip(parts, depth, strict=True)]
        seen: dict[str, int] = {}
        for name in names:
            seen[name] = seen.get(name, 0) + 1
        clash = [i for i, name in enumerate(names) if seen[name] > 1]
        if not clash:
            return [plot.with_name(f"{plot.stem}-{name}{plot.suffix}") for name in names]
        grow = [i for i in clash if depth[i] < len(parts[i])]
        if not grow:
            return [plot.with_name(f"{plot.stem}-{name}{plot.suffix}") for name in _numbered(files, names)]
        for i in grow:
            depth[i] += 1


def _numbered(files: list[Path], names: list[str]) -> list[str]:
    """`names` made unique when whole paths still clash once joined with '-' (a-b/c.mcap and a/b/c.mcap are
    both a-b-c): the second and later of a name get -2, -3, ...; one file given twice is an InputError."""
    import os

    from ..base.errors import InputError

    first: dict[str, str] = {}
    for f in files:
        real = os.path.realpath(f)
        if real in first:
            raise InputError(f"{f}: given twice (as {first[real]}); with --plot each file is plotted once")
        first[real] = str(f)
    taken = set(names)
    out: list[str] = []
    for name in names:
        if name not in out:
            out.append(name)
            continue
        k = 2
        while f"{name}-{k}" in taken:
            k += 1
        taken.add(f"{name}-{k}")
        out.append(f"{name}-{k}")
    return out


def check_plot_outputs(paths: list[Path], force: bool) -> None:
    """Refuse a missing matplotlib (the plot extra), a bad plot suffix or a plot path outputs.check_output
    refuses (an existing plot without --force, a folder or device in the way, a missing or read-only folder),
    before any work."""
    from ..base.errors import InputError
    from ..base.extras import require
    from ..base.outputs import check_output

    if paths:
        require("matplotlib", for_="--plot")
    for p in paths:
        if p.suffix.lower() not in PLOT_SUFFIXES:
            raise InputError(f"{p}: plot format must be one of {', '.join(PLOT_SUFFIXES)}")
        check_output(p, force=force, what="plot")


def save_plot(data, path: Path, force: bool, kind: str = "auto", all_labels: bool = False) -> str:
    """Draw `data` (report.RunData) into `path` atomically (a temporary file renamed when the figure is
    complete); returns the line that says so (with the labels left out where they would overlap)."""
    import matplotlib

    from ..base.outputs import atomic_output
    from .plot import plot_run

    with (
        atomic_output(path, force=force, what="plot") as f,
        matplotlib.rc_context({"savefig.format": path.suffix.lower().lstrip(".")}),
    ):
        drawn = plot_run(data, f, kind=kind, all_labels=all_labels)
    note = (
        f" ({drawn.dropped} of {drawn.dropped + drawn.placed} labels left out: no room without overlap)"
        if drawn.dropped
        else ""
    )
    return f"{path}: plot written, {drawn.kind}{note}"
