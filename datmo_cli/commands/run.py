"""`datmo run`: segment, extract features and track in one pass per input, in parallel; then the report."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from ..bounds import OPTIONS
from ..report import FORMATS, SORT_KEYS
from .options import config_options, force_option, input_options, no_stdout, output_option, param_option, quiet_option
from .types import option

if TYPE_CHECKING:
    from ..config import DatmoConfig


def _scan_count(spec: str) -> int | None:
    """The scans of a local log from its summary (no payloads read), or None (remote, unreadable: the
    task itself says what is wrong)."""
    from ..batch import local, remote
    from ..log import mcapio

    if remote(spec):
        return None
    try:
        return mcapio.summary(local(spec), warn=False).topics()[mcapio.TOPIC_SCAN].count or None  # the task warns
    except Exception:  # only an estimate for the bar
        return None


class _BatchProgress:
    """One progress bar over the batch's scans on stderr, each scan counted once (all stages run in one pass
    over it), across every worker; beside it the inputs done of all, scans/s and failures. The total is the
    scans of the inputs to run, from their summaries; an input whose count is not known up front adds it
    when it starts, and a failed one its scans done."""

    def __init__(self, batch) -> None:
        import time

        from ..progress import bar

        self.t0 = time.perf_counter()
        self.n_inputs = batch.total
        self.index = {t.input: t.index for t in batch.tasks}
        self.totals: dict[int, int | None] = {t.index: _scan_count(t.input) for t in batch.tasks}
        self.running: dict[int, int] = {}
        self.scans = self.failed = self.inputs = 0
        self._bar = bar("run", self._total(), info=True)

    def _total(self) -> int | None:
        return sum(n for n in self.totals.values() if n is not None) or None

    def __enter__(self) -> _BatchProgress:
        self.bar = self._bar.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self._bar.__exit__(*exc)

    def _show(self) -> None:
        import time

        scans = self.scans + sum(self.running.values())
        rate = scans / max(time.perf_counter() - self.t0, 1e-9)
        info = f"inputs {self.inputs}/{self.n_inputs}  {rate:,.0f} scans/s" + (
            f"  {self.failed} failed" if self.failed else ""
        )
        self.bar.update(scans, self._total(), info=info)

    def record(self, rec: dict) -> None:
        from ..batch import DONE, FAILED

        if rec["status"] == DONE:
            for line in rec.get("notes") or ():
                self.bar.tell(line)
        i = self.index.get(rec["input"], -1)
        done = self.running.pop(i, 0)
        if rec["status"] == DONE:
            self.scans += rec["scans"]
            self.totals[i] = rec["scans"]
        elif i in self.totals:  # failed or cancelled: what it did is all it will do
            self.scans += done
            self.totals[i] = done
        self.inputs += 1
        self.failed += rec["status"] == FAILED
        self._show()

    def progress(self, index: int, done: int, total: int) -> None:
        self.running[index] = done
        self.totals[index] = total
        self._show()


@click.command(name="run")
@click.argument("inputs", nargs=-1, required=True)
@output_option(
    "Folder (or fsspec URL) for the outputs: OUT_DIR/NAME.mcap per input file, the relative path "
    "for logs found in a folder; and OUT_DIR/manifest.jsonl, the batch's ledger (created if missing).",
    "-o",
    "--output-dir",
    "out_dir",
    type=str,
    callback=no_stdout("outputs", "a folder"),
)
@option(
    "-j",
    "--jobs",
    bound=OPTIONS["jobs"],
    default=None,
    help="Inputs processed at once, in separate processes on this machine [default: all cores].",
)
@click.option(
    "--scheduler",
    metavar="ADDRESS",
    default=None,
    help="Run one task per input on a running Dask scheduler (tcp://host:8786), or on a local cluster of N "
    "worker processes started for the run (local[:N]). Needs pip install 'datmo-cli[dask]'.",
)
@option(
    "--retries",
    bound=OPTIONS["retries"],
    default=2,
    show_default=True,
    help="With --scheduler: times a task is retried after an unexpected error or the death of its worker.",
)
@force_option(
    "Redo every input and overwrite existing outputs (and plots); without it "
    "inputs the manifest lists as done with the same input and parameters are skipped."
)
@config_options(
    "TOML file of parameters: its [features] table as for datmo features, its [track] table as for datmo track."
)
@click.option(
    "--plot",
    is_flag=True,
    help="Also draw each run from above into OUT_DIR/NAME.png (needs the plot extra, matplotlib).",
)
@click.option(
    "--bag-dir",
    is_flag=True,
    help="Write each output as a ROS 2 bag folder for ros2 bag play: OUT_DIR/NAME/ holding NAME_0.mcap "
    "(the output, as the manifest names it) and metadata.yaml.",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(FORMATS),
    default="rich",
    show_default=True,
    help="Format of the report printed at the end (see datmo report).",
)
@option("--top", bound=OPTIONS["top"], default=None, help="Tracks in the report's track table (0: all).")
@click.option(
    "--sort",
    type=click.Choice(SORT_KEYS),
    default="lifetime",
    show_default=True,
    help="Order of the report's track table.",
)
@click.option("--no-report", is_flag=True, help="Do not print the report.")
@click.option(
    "--markers/--no-markers",
    default=False,
    show_default=True,
    help="Also store /datmo/markers/* (Foxglove drawings) in the outputs; datmo play draws them from the "
    "tracks and features anyway.",
)
@click.option(
    "--covariance",
    is_flag=True,
    help="Store each track's covariance in /datmo/tracks (otherwise its 16 numbers are NaN).",
)
@param_option("track.ego_motion")
@param_option("track.hindsight_lag")
@param_option("features.leg_model")
@option(
    "--threads",
    bound=OPTIONS["threads"],
    default=None,
    help="Threads for each input's per-scan perception (segmentation, features, leg detector) [default: "
    "all cores; one in each of several local jobs at once, and in each task on a Dask worker]; the "
    "results are the same for any number.",
)
@input_options
@quiet_option
def command(
    inputs: tuple[str, ...],
    out_dir: str,
    jobs: int | None,
    scheduler: str | None,
    retries: int,
    force: bool,
    cfg: DatmoConfig,
    plot: bool,
    bag_dir: bool,
    fmt: str,
    top: int | None,
    sort: str,
    no_report: bool,
    markers: bool,
    covariance: bool,
    threads: int | None,
    topic: str | None,
    odom_topic: str | None,
) -> None:
    """Segment, extract features and track each input in one pass, then print the report.

    Each output holds the input's channels and /datmo/segments, /datmo/features, /datmo/landmarks and
    /datmo/tracks (with --markers the Foxglove markers too, with --covariance the tracks' covariance), with
    the same messages as datmo segment, datmo features and datmo track run one after another. The report is
    gathered as the outputs are written. INPUTS are files, folders (searched recursively for .mcap logs) and globs, or
    fsspec URLs. ROS 1 bags and ROS 2 bag folders or their .db3 (and any input with --topic) are converted as
    by datmo import by the input's own task, into a temporary MCAP beside its output (removed when the task
    ends); the output is named after the bag and its provenance names the bag. Inputs run in parallel in local
    processes (--jobs) or on a Dask cluster (--scheduler); a failing input is reported and the others'
    outputs are kept (the exit status is then 1). A tcp:// scheduler lets whoever reaches it run code as its
    user; a tls:// one takes the certificate of the Dask configuration; local[:N] (N at most the cores) speaks
    TLS with a temporary certificate, so no other user of the machine can reach it.

    OUT_DIR/manifest.jsonl gets one line per input as it finishes (input SHA-256, output, status, scans,
    tracks by class, parameters' hash, which counts --topic and --odom-topic). Running the same command again
    skips the inputs already done with the same input and parameters, bags without converting them, and does
    the rest (after a failure or Ctrl-C); --force redoes all.

    With --bag-dir each output is a ROS 2 bag folder, OUT_DIR/NAME/ holding NAME_0.mcap and metadata.yaml, which
    ros2 bag play and other bag tools open (build datmo_msgs for the /datmo topics); plots stay OUT_DIR/NAME.png.

    Example: datmo run sample_logs/hall.mcap sample_logs/corridor.mcap -o out --plot

    Example: datmo run 'logs/**/*.mcap' -o out --scheduler tcp://10.0.0.5:8786
    """
    from ..batch import DONE, FAILED, SKIPPED, SUMMARY_KEY, RunOptions, folder_lock, remote
    from ..errors import DatmoError
    from ..perception.threads import set_default
    from ..text import printable

    set_default(threads)  # a run-time setting: not among the parameters (the outputs do not depend on it)
    _check_options(out_dir, scheduler, jobs, plot, bag_dir)
    _check_leg_model(cfg)
    options = RunOptions(markers=markers, covariance=covariance, topic=topic, odom_topic=odom_topic, bag_dir=bag_dir)
    with folder_lock(out_dir):  # one batch at a time in a folder: a second is refused, naming the first
        records, where, seconds, plot_of = _run_batch(
            inputs, out_dir, cfg, options, force, threads, plot, bag_dir, scheduler, jobs, retries
        )
        _final_table(records, seconds, where)
        for r in records:
            if r["status"] == FAILED:
                click.echo(f"datmo: error: {printable(r['error'])}", err=True)
        ok = [r for r in records if r["status"] in (DONE, SKIPPED)]
        if ok and (not no_report or plot_of) and not remote(out_dir):
            made = {Path(r["output"]) for r in ok if r["status"] == DONE}
            _report(
                [Path(r["output"]) for r in ok],
                [p for o, p in plot_of.items() if Path(o) in made],
                None if no_report else fmt,
                top,
                sort,
                force,
                [r.get(SUMMARY_KEY) for r in ok],
            )
    failed = len(records) - len(ok)
    if failed == len(records) and failed > 1:
        raise DatmoError(f"all {failed} inputs failed")
    if failed and len(records) > 1:
        raise DatmoError(f"{failed} of {len(records)} inputs failed; the other outputs are complete")
    if failed:
        raise SystemExit(1)  # the one error is printed above


def _run_batch(inputs, out_dir, cfg, options, force, threads, plot, bag_dir, scheduler, jobs, retries):
    """Prepare the batch and run it (the output folder locked by the caller): (its manifest lines, where they
    ran, seconds, each output's plot path)."""
    from ..batch import LocalExecutor, prepare, run_many
    from ..cli import invocation
    from ..config import provenance_line
    from ..log import bagdir

    batch = prepare(
        list(inputs),
        out_dir,
        config=cfg,
        options=options,
        force=force,
        command_line=provenance_line(invocation("run")),
        threads=threads,
    )
    plot_of = (
        {t.output: bagdir.plot_path(t.output) if bag_dir else Path(t.output).with_suffix(".png") for t in batch.tasks}
        if plot
        else {}
    )
    plots = list(plot_of.values())
    if plots:
        from ..plot_files import check_plot_outputs

        check_plot_outputs(plots, force)
    if scheduler is not None and batch.tasks:
        from ..cluster import DaskExecutor

        executor = DaskExecutor(scheduler, retries=retries)
    else:
        executor = LocalExecutor(jobs)
        if batch.tasks and min(executor.workers, len(batch.tasks)) > 1:
            _warm_up()  # a pool: compiled (or loaded) once before the workers fork
        # else one process compiles or loads just the kernels it runs (the line saying so came first)
    import time

    t0 = time.perf_counter()
    try:
        with _BatchProgress(batch) as bar:
            records = run_many(batch, executor, on_record=bar.record, on_scans=bar.progress)
    finally:
        executor.close()
    return records, executor.where, time.perf_counter() - t0, plot_of


def _check_options(out_dir: str, scheduler: str | None, jobs: int | None, plot: bool, bag_dir: bool) -> None:
    """Options that do not go together are one error, before any input starts."""
    from ..batch import remote
    from ..errors import DatmoError

    if scheduler is not None and jobs is not None:
        raise DatmoError("--jobs is for local runs; with --scheduler the cluster's workers run the inputs")
    if plot and remote(out_dir):
        raise DatmoError(f"{out_dir}: --plot needs a local output folder")
    if bag_dir and remote(out_dir):
        raise DatmoError(f"{out_dir}: --bag-dir needs a local output folder")


def _check_leg_model(cfg: DatmoConfig) -> None:
    """A leg model that does not load is one error, before any input starts."""
    from ..perception.leg_model import load_leg_model

    load_leg_model(cfg.features.leg_model)


FINAL_ROWS = 50


def _final_table(records: list[dict], seconds: float, where: str) -> None:
    """The batch's table on stderr (every input up to FINAL_ROWS, then only failures) and its totals line;
    nothing under --quiet (failures are said as errors all the same)."""
    from ..batch import DONE, FAILED, SKIPPED
    from ..progress import console, quiet
    from ..progress import table as make_table

    if quiet():
        return

    done = [r for r in records if r["status"] == DONE]
    scans = sum(r["scans"] for r in done)
    shown = records if len(records) <= FINAL_ROWS else [r for r in records if r["status"] == FAILED][:FINAL_ROWS]
    if shown:
        err = console(stderr=True)
        table = make_table(err, title_justify="left")
        for col in ("input", "status", "scans", "scans/s", "tracks", "people", "output or error"):
            table.add_column(
                col, justify="right" if col in ("scans", "scans/s", "tracks", "people") else "left", overflow="fold"
            )
        for r in shown:
            t = r.get("tracks") or {}
            table.add_row(
                Path(r["input"]).name,
                r["status"],
                f"{r['scans']:,}" if r["status"] != FAILED else "",
                f"{r['scans_per_s']:,.0f}" if r["status"] == DONE else "",
                str(t.get("confirmed", "")),
                str(t.get("person", "")),
                r["error"] if r["status"] == FAILED else r["output"],
            )
        err.print(table)
    counts = {s: sum(r["status"] == s for r in records) for s in (DONE, SKIPPED, FAILED)}
    rate = scans / seconds if seconds > 0 else 0.0
    click.echo(
        f"{len(records)} input{'s' if len(records) != 1 else ''}: {counts[DONE]} done, {counts[SKIPPED]} "
        f"skipped (already in the manifest), {counts[FAILED]} failed; {scans:,} scans in {seconds:.1f} s on "
        f"{where} ({rate:,.0f} scans/s)",
        err=True,
    )


def _warm_up() -> None:
    """Load the numba kernels before the clock of any input starts; the first run after an install
    compiles them (minutes, then cached), which is said at once (numba_runtime.say_compiling, terminal or
    not) with a progress bar in a terminal, rather than counted in the inputs' speed."""
    import time

    from ..batch import ensure_warm
    from ..numba_runtime import cache_looks_stale, say_compiling
    from ..progress import bar, say

    t0 = time.perf_counter()
    compiled = cache_looks_stale()  # before anything is compiled
    say_compiling()  # said once a process (the command line's first step has said it)
    with bar(f"{'compiling' if compiled else 'loading'} the numba kernels", None, unit="steps") as b:
        ensure_warm(b.update)  # once per process: the --jobs pool forks after it
    seconds = time.perf_counter() - t0
    if compiled or seconds > 2.0:
        say(f"compiled the numba kernels in {seconds:.0f} s (first run after an install; cached for the next runs)")


def _report(
    outputs: list[Path],
    plots: list[Path],
    fmt: str | None,
    top: int | None,
    sort: str,
    force: bool = False,
    made: list | None = None,
) -> None:
    """Draw the plots, and print the report of `outputs` in `fmt` (None: no report). `made`: each output's
    report as its task gathered it while writing it (report.RunSummary), None for an output not made by
    this run (skipped: already in the manifest), which is read in one streaming pass."""
    from ..pipeline import read_run_data
    from ..report import console, render, summarise, summarise_file

    summaries = []
    made = made or [None] * len(outputs)
    for i, out in enumerate(outputs):
        if not plots:  # a plot draws every scan and state, so it decodes the whole run
            if fmt:
                summaries.append(made[i] if made[i] is not None else summarise_file(out))
            continue
        from ..plot_files import save_plot
        from ..text import printable

        data = read_run_data(out, keep_scans=True)
        summaries.append(made[i] if made[i] is not None else summarise(data))
        click.echo(printable(save_plot(data, plots[i], force)), err=True)
    if fmt == "rich":
        render(summaries, fmt, top=top, sort=sort, console=console())
    elif fmt:
        click.echo(render(summaries, fmt, top=top, sort=sort), nl=False)
