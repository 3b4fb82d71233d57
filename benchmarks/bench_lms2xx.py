"""LMS2xx figures: B0 decode speed, incremental parser throughput, and `record` from the emulator at 500 kBd."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import Row, best_of, print_lines, print_table

CAPTURE = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "lms2xx" / "lms2xx_b0_361_mm.bin"


def _telegram() -> tuple[bytes, str]:
    from datmo_cli.lms2xx import protocol as P

    if CAPTURE.exists():
        return CAPTURE.read_bytes(), "real capture"
    values = np.random.default_rng(0).integers(400, 5000, 361).astype(np.uint16)
    return P.reply_frame(P.encode_b0(values)), "synthetic telegram"


def bench_decode(n: int = 2000) -> Row:
    from datmo_cli.lms2xx import protocol as P

    raw, what = _telegram()

    def run() -> None:
        for _ in range(n):
            f = P.parse_frame(raw)
            t = P.decode_b0(f.data, f.status)
            P.values_to_ranges(t.values, t.units, 0)

    return Row("B0 decode: CRC + parse + ranges (361 values)", n, best_of(run), what)


def bench_parser(n: int = 2000, chunk: int = 4096) -> tuple[Row, float]:
    from datmo_cli.lms2xx.frame_parser import FrameParser

    raw, _ = _telegram()
    rng = np.random.default_rng(1)
    garbage = [
        rng.integers(0, 256, int(k), np.uint8).tobytes() if k else b""
        for k in rng.integers(0, 2, n) * rng.integers(1, 20, n)
    ]
    stream = b"".join(g + raw for g in garbage)

    def run() -> None:
        parser = FrameParser()
        for i in range(0, len(stream), chunk):
            parser.feed(stream[i : i + chunk])
        assert parser.stats.frames == n

    seconds = best_of(run)
    mb_s = len(stream) / seconds / 1e6
    return Row("incremental parser (4 KiB chunks, garbage)", n, seconds, f"{mb_s:.2f} MB/s"), mb_s


def bench_record(n: int, realtime: bool) -> Row:
    from datmo_cli.lms2xx.driver import LMS2xx
    from datmo_cli.lms2xx.emulator import Emulator
    from datmo_cli.lms2xx.recorder import record
    from datmo_cli.logs import mcapio
    from datmo_cli.passes.simulated import SceneSource

    with tempfile.TemporaryDirectory() as d, Emulator(SceneSource("hall"), realtime=realtime) as emu:
        driver = LMS2xx(emu.device_path, baud=500000)
        writer = mcapio.LogWriter(Path(d) / "run.mcap", streaming=True)
        t0 = time.perf_counter()
        result = record(driver, writer, max_scans=n)
        total = time.perf_counter() - t0
        got = len(mcapio.read_run(Path(d) / "run.mcap"))
    note = (
        f"scan period (37.5 Hz); {total - result.seconds:.2f} s connect+stop"
        if realtime
        else "line-limited: 732 B at 50 kB/s"
    )
    return Row(
        f"record from emulator, 500 kBd, {'real time' if realtime else 'as fast as the line'}",
        got,
        result.seconds,
        note,
    )


def bench_record_75hz(seconds: float = 30.0) -> tuple[Row, int, int, float]:
    """`datmo record` in its own process against the emulator at 500 kBd, 180 degrees at 1 degree (75 Hz),
    in real time for `seconds`: (row, scans written, scans dropped, recorder CPU time / wall time)."""
    import json
    import resource
    import subprocess
    import sys

    from datmo_cli.lms2xx.emulator import Emulator
    from datmo_cli.logs import mcapio
    from datmo_cli.passes.simulated import SceneSource

    datmo = Path(sys.executable).with_name("datmo")
    with (
        tempfile.TemporaryDirectory() as d,
        Emulator(SceneSource("hall", duration=seconds + 30), resolution_deg=1.0, realtime=True) as emu,
    ):
        out = Path(d) / "run.mcap"
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(
            [
                str(datmo),
                "record",
                "--port",
                emu.device_path,
                "--baud",
                "500000",
                "--resolution",
                "1",
                "--indices",
                "--duration",
                str(seconds),
                "-o",
                str(out),
            ],
            check=True,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        got = len(mcapio.read_run(out))
        stats = json.loads(json.dumps(mcapio.summary(out).metadata.get("lms2xx.stats", {})))
        dropped = int(stats.get("dropped", -1))
    row = Row(
        "record 500 kBd, 180°/1° (75 Hz), own process, real time",
        got,
        wall,
        f"dropped {dropped}, CPU {100 * cpu / wall:.1f}% of a core (target < 10%)",
    )
    return row, got, dropped, cpu / wall


def main() -> None:
    decode = bench_decode()
    parser, mb_s = bench_parser()
    live, got, dropped, cpu = bench_record_75hz()
    rows = [decode, parser, bench_record(75, True), bench_record(150, False), live]
    print_table("LMS2xx protocol and record (one core)", rows)
    print_lines(
        "LMS2xx figures",
        [
            f"B0 decode: {decode.scans_per_s:,.0f} telegrams/s",
            f"parser throughput: {mb_s:.2f} MB/s (500 kBd needs 0.05 MB/s)",
            f"record at 500 kBd: {rows[2].scans_per_s:.1f} scans/s real time, "
            f"{rows[3].scans_per_s:.1f} scans/s line-limited",
            f"record 30 s at 75 Hz (1°): {got} scans, {dropped} dropped, recorder CPU "
            f"{100 * cpu:.1f}% of one core (target: none lost, < 10%)",
        ],
    )


if __name__ == "__main__":
    main()
