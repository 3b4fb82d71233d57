"""Reading processed logs for the report, and the one-pass run (segment, features, track) behind `datmo run`.

The one pass calls the same functions the stage commands write their channels with: perception's
`derive_features` (the channels of `datmo segment` and `datmo features`, and the RunFeatures) and
tracking's `derive_tracks` (the channels of `datmo track`), so its output holds the same payloads as the
three stages run one after another, without intermediate files.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from .errors import DatmoError, InputError
from .log import mcapio
from .report import RunData

REPORT_TOPICS = (mcapio.TOPIC_SCAN, mcapio.TOPIC_ODOM, mcapio.TOPIC_FEATURES, mcapio.TOPIC_LANDMARKS,
                 mcapio.TOPIC_TRACKS)


def read_run_data(path: str | Path, *, keep_scans: bool = False, ground_truth: bool = False) -> RunData:
    """The channels of a processed log that `datmo report` needs, decoded.

    Raises MissingChannelError naming the command to run first when /scan or /datmo/tracks is missing.
    """
    topics = REPORT_TOPICS + ((mcapio.TOPIC_GROUND_TRUTH,) if ground_truth else ())
    return RunData.from_log(mcapio.read_log(path, topics=topics), keep_scans=keep_scans)


# ------------------------------------------------------------------------------------------ datmo run


@dataclass
class JobResult:
    """The outcome of one input of `datmo run`: its output, or the one-line error that stopped it."""

    input: Path
    output: Path
    scans: int = 0
    seconds: float = 0.0
    error: str | None = None


def output_paths(inputs: list[Path], out_dir: Path) -> list[Path]:
    """OUT_DIR/NAME.mcap for each input; refuses two inputs with the same name."""
    outs = [out_dir / f"{Path(p).stem}.mcap" for p in inputs]
    seen: dict[Path, Path] = {}
    for src, out in zip(inputs, outs, strict=True):
        if out in seen:
            raise InputError(f"{src}: same output name as {seen[out]} ({out}); rename one of them")
        seen[out] = src
    return outs


def run_many(inputs: list[Path], out_dir: Path, *, jobs: int | None = None, force: bool = False,
             params: dict | None = None, command_line: str | None = None,
             progress: Callable[[int, int, int], None] | None = None) -> list[JobResult]:
    """Process every input into OUT_DIR/NAME.mcap, `jobs` at a time in separate processes (default: all
    cores). A failing input gives a JobResult with its error; the others go on. `progress(i, done, total)`
    reports scans done for input i (called in this process)."""
    outs = output_paths(inputs, out_dir)
    jobs = min(jobs or os.cpu_count() or 1, len(inputs))
    args = [(Path(src), out, force, params, command_line) for src, out in zip(inputs, outs, strict=True)]
    if jobs <= 1:
        return [_job(i, a, progress) for i, a in enumerate(args)]
    warm_up()
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    results: list[JobResult | None] = [None] * len(args)
    with multiprocessing.Manager() as manager, ProcessPoolExecutor(max_workers=jobs) as pool:
        queue = manager.Queue()
        futures = {pool.submit(_job_queued, i, a, queue): i for i, a in enumerate(args)}
        pending = set(futures)
        while pending:
            done, pending = wait(pending, timeout=0.1, return_when=FIRST_COMPLETED)
            _drain(queue, progress)
            for fut in done:
                i = futures[fut]
                try:
                    results[i] = fut.result()
                except BrokenProcessPool as exc:
                    results[i] = JobResult(args[i][0], args[i][1], error=f"{args[i][0]}: worker died ({exc})")
        _drain(queue, progress)
    return [r for r in results if r is not None]


def warm_up() -> None:
    """Compile every numba kernel of the pipeline in this process (or load it from numba's cache) on short
    simulated runs of the hall (people, a platform, columns, benches, occlusions) and of the patrol scene
    (odometry), before any input's clock starts and before worker processes start: they then inherit the
    compiled kernels (fork) or find the cache complete (spawn), and never compile one kernel at once (a
    first run after an install would otherwise have every worker writing the same cache files)."""
    from .perception.egomotion import odometry_for
    from .sim.simulate import simulate_scene

    for scene in ("hall", "patrol"):
        sim = simulate_scene(scene, duration=8.0)
        derive(sim.run, sim.odometry)
    odometry_for(sim.run, None, "on")   # scan matching, for logs without odometry


def _drain(queue, progress) -> None:  # noqa: ANN001
    import queue as queue_mod

    while True:
        try:
            i, done, total = queue.get_nowait()
        except queue_mod.Empty:
            return
        if progress:
            progress(i, done, total)


def _job_queued(i: int, args: tuple, queue) -> JobResult:  # noqa: ANN001 - a Manager queue proxy
    return _job(i, args, lambda i, d, t: queue.put((i, d, t)))


def _job(i: int, args: tuple, report: Callable[[int, int, int], None] | None) -> JobResult:
    """Run one input; every failure becomes the JobResult's one-line error."""
    src, out, force, params, command_line = args
    t0 = time.perf_counter()
    try:
        scans = process_file(src, out, force=force, params=params, command_line=command_line,
                             progress=(lambda d, t: report(i, d, t)) if report else None)
    except DatmoError as exc:
        text = str(exc)
        return JobResult(src, out, error=text if text.startswith(str(src)) else f"{src}: {text}")
    except Exception as exc:  # noqa: BLE001 - one input's bug must not lose the others' results
        return JobResult(src, out, error=f"{src}: failed: {type(exc).__name__}: {exc}")
    return JobResult(src, out, scans, time.perf_counter() - t0)


def estimated_odometry(run, odometry, mode: str) -> tuple:  # noqa: ANN001 - ScanRun, Odometry | None
    """(odometry to track in, {"/odom": channel} when it was estimated from the scans here, else {}): a log
    without odometry whose scanner moves is tracked in poses from scan matching (see perception.egomotion),
    written to /odom (frame scan_odom) so the output holds the frame its world positions are in."""
    from .log import types
    from .perception.egomotion import odometry_for

    odometry, estimated = odometry_for(run, odometry, mode)
    if not estimated:
        return odometry, {}
    return odometry, {mcapio.TOPIC_ODOM: (types.ODOMETRY, odometry.stamps, mcapio.encode_odometry(odometry))}


def derive(run, odometry, params: dict | None = None,  # noqa: ANN001 - ScanRun, Odometry | None
           progress: Callable[[int, int], None] | None = None) -> tuple[dict[str, tuple], dict]:
    """Every derived channel of a run, {topic: (msgtype, stamps, payloads)}, and the effective parameters.

    `params` may hold "track" (a TrackingParams) and "features" (a FeatureParams). `progress(done, total)`
    follows the scans through feature extraction and then tracking (each half of the total).
    """
    from .perception.features import derive_features
    from .perception.params import FeatureParams
    from .tracking.params import TrackingParams
    from .tracking.pipeline import derive_tracks, iter_run_features

    params = params or {}
    track_params = params.get("track") or TrackingParams()
    feature_params = params.get("features") or FeatureParams()
    odometry, odom_channel = estimated_odometry(run, odometry, track_params.ego_motion)
    n = len(run)
    if progress:
        progress(0, 2 * n)
    channels, features = derive_features(run, odometry=odometry, params=feature_params,
                                         progress=(lambda d, t: progress(d, 2 * n)) if progress else None)
    tracks = derive_tracks(run, list(iter_run_features(features)), odometry=odometry, params=track_params,
                           learned=feature_params.leg_model != "paper",
                           progress=(lambda d, t: progress(n + d, 2 * n)) if progress else None)
    from .perception.features import leg_model_provenance

    effective = {"features": feature_params.to_dict(), "track": track_params.to_dict(),
                 "leg_model": leg_model_provenance(feature_params.leg_model)}
    return {**odom_channel, **channels, **tracks}, effective


def process_file(src: str | Path, out: str | Path, *, force: bool = False, params: dict | None = None,
                 command_line: str | None = None, progress: Callable[[int, int], None] | None = None) -> int:
    """Segment, extract features and track `src` in one pass into `out` (see module docstring); returns
    the number of scans. `progress(done, total)` is called as scans are processed."""
    log = mcapio.read_log(src, topics=None)
    run = mcapio.run_from_log(log)
    odometry = mcapio.odometry_from_log(log)
    derived, effective = derive(run, odometry, params, progress)
    provenance = mcapio.Provenance("run", effective, [src], command_line)
    with mcapio.LogWriter(out, force=force, provenance=provenance) as writer:
        writer.copy_from(log, exclude=list(derived))
        for topic, (msgtype, stamps, payloads) in derived.items():
            writer.write_many(topic, msgtype, stamps, payloads)
    return len(run)
