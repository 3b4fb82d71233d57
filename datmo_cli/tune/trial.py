"""One evaluation of `datmo tune`: one setting on one log (or a prefix of it), as a batch task. The worker runs
`datmo run`'s pass (pipeline.process_file) into a temporary output, scores it as `datmo evaluate` does
(evaluate.files.score_file), removes the output and returns a manifest line holding the log's figures
(objective.log_metrics). The same code as the two commands, so a best setting's figure is what `datmo run`
and `datmo evaluate` then give. Also: the logs' prefixes (the first seconds of a log, every channel, as a
log of its own) that successive halving scores settings on first.

Stamps in int64 ns, durations in seconds.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ..batch.manifest import DONE
from ..batch.task import Cancelled, Task, failed, follow, record


@dataclass(frozen=True)
class LogInput:
    """A log of the tune: its path, ground truth (None: its /datmo/ground_truth channel; else a CSV), SHA-256,
    scans and duration (s, first to last scan)."""

    path: str
    gt_csv: str | None
    sha256: str
    scans: int
    seconds: float

    @property
    def name(self) -> str:
        return Path(self.path).name


@dataclass
class EvalTask(Task):
    """A batch task scoring `config` on `log` (a local path: the whole log or a prefix made by `prefix_log`)
    against `gt_csv` (None: the log's channel). `input` is the evaluation's key in the manifest; `output` the
    temporary output, removed once scored; `duration` the seconds scored (for the rates)."""

    log: str = ""
    gt_csv: str | None = None
    duration: float = 0.0

    def run(
        self,
        *,
        cancelled: Callable[[], bool] | None = None,
        scans: Callable[[int, int], None] | None = None,
        raise_unexpected: bool = False,
    ) -> dict:
        """The manifest line of this evaluation: done with `metrics`, or failed with the one-line error."""
        from ..base.errors import DatmoError
        from ..evaluate.files import score_file
        from ..passes import pipeline
        from ..perception.threads import set_default
        from .objective import log_metrics

        set_default(self.threads or 1)  # evaluations run side by side, one per process
        t0 = time.perf_counter()
        try:
            n = pipeline.process_file(
                self.log, self.output, force=True, config=self.config, progress=follow(cancelled, scans)
            )
            result = score_file(Path(self.output), gt_csv=Path(self.gt_csv) if self.gt_csv else None)
        except Cancelled:
            return record(self, "cancelled")
        except DatmoError as exc:
            return failed(self, str(exc))
        except Exception as exc:
            if raise_unexpected:
                raise
            return failed(self, f"failed: {type(exc).__name__}: {exc}")
        finally:
            _remove(self.output)
        seconds = time.perf_counter() - t0
        return record(
            self,
            DONE,
            scans=n,
            seconds=round(seconds, 3),
            scans_per_s=round(n / seconds, 1) if seconds > 0 else 0.0,
            metrics=log_metrics(result["scores"], self.duration),
        )


def _remove(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def log_input(path: str | Path) -> LogInput:
    """A log of the tune, checked: it has scans, and ground truth (its /datmo/ground_truth channel, else a CSV
    beside it named NAME.gt.csv); InputError in one line naming the file otherwise."""
    from ..base.errors import InputError
    from ..logs import mcapio

    path = Path(path)
    contents = mcapio.summary(path)  # InputError for a missing or unreadable file
    topics = contents.topics()
    scan = topics.get(mcapio.TOPIC_SCAN)
    if scan is None or scan.count < 2:
        raise InputError(f"{path}: fewer than 2 scans on {mcapio.TOPIC_SCAN}; nothing to tune on")
    gt = topics.get(mcapio.TOPIC_GROUND_TRUTH)
    csv = path.with_name(path.name.removesuffix(".mcap") + ".gt.csv")
    if gt is None or not gt.count:
        if not csv.is_file():
            raise InputError(
                f"{path}: no ground truth: no messages on {mcapio.TOPIC_GROUND_TRUTH} and no {csv.name} beside it "
                "(stamp_ns,id,x,y as datmo evaluate --gt reads)"
            )
    gt_csv = None if gt is not None and gt.count else str(csv.resolve())
    return LogInput(
        str(path.resolve()),
        gt_csv,
        mcapio.sha256_of(path),
        scan.count,
        (scan.last_ns - scan.first_ns) / 1e9,
    )


def prefix_scans(log: LogInput, fraction: float) -> int:
    """The scans of `log`'s prefix of `fraction` of it (all for 1)."""
    return log.scans if fraction >= 1 else max(2, int(round(log.scans * fraction)))


def prefix_log(log: LogInput, scans: int, folder: Path) -> tuple[str, str | None, float]:
    """(path, ground-truth CSV or None, seconds) of the first `scans` scans of `log` as a log of its own in
    `folder` (every channel up to the last kept scan's stamp; made once, reused while complete), or the log
    itself for all its scans."""
    if scans >= log.scans:
        return log.path, log.gt_csv, log.seconds
    from ..logs import mcapio

    stem = f"{Path(log.path).name.removesuffix('.mcap')}-{log.sha256[:12]}-{scans}"
    out = folder / f"{stem}.mcap"
    csv_out = folder / f"{stem}.gt.csv" if log.gt_csv else None
    contents = mcapio.read_log(log.path, topics=None)  # type: ignore[arg-type]  # None: every topic
    stamps = contents.messages[mcapio.TOPIC_SCAN][0]
    last = sorted(stamps)[scans - 1]
    if not out.is_file():
        folder.mkdir(parents=True, exist_ok=True)
        with mcapio.LogWriter(out, force=True) as w:
            for ch in contents.channels.values():
                if ch.topic not in contents.messages:
                    continue
                w.channel(
                    ch.topic,
                    ch.msgtype,
                    schema_text=ch.schema_data.decode("utf-8", "replace"),
                    schema_encoding=ch.schema_encoding,
                    message_encoding=ch.message_encoding,
                    metadata=ch.metadata,
                )
                kept = [(t, p) for t, p in zip(*contents.messages[ch.topic], strict=True) if t <= last]
                w.write_many(ch.topic, ch.msgtype, [t for t, _ in kept], [p for _, p in kept])
    if csv_out is not None and log.gt_csv is not None and not csv_out.is_file():
        _prefix_csv(Path(log.gt_csv), csv_out, last)
    first = min(stamps)
    return str(out), str(csv_out) if csv_out else None, (last - first) / 1e9


def _prefix_csv(src: Path, dst: Path, last: int) -> None:
    """The rows of ground-truth CSV `src` stamped at or before `last` (ns), with its header, into `dst`."""
    from ..base.outputs import atomic_output

    lines = src.read_text(encoding="utf-8-sig").splitlines(keepends=True)
    kept = [
        line
        for line in lines
        if not line.split(",", 1)[0].strip().lstrip("-").isdigit() or int(line.split(",", 1)[0]) <= last
    ]
    with atomic_output(dst, force=True, what="ground-truth prefix") as f:
        f.write("".join(kept).encode("utf-8"))
