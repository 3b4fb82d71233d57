"""Inputs of `datmo import` for the streaming tests: small hand-made logs of every kind and edge (stamps
repaired or synthesised, flipped beams, ODOM poses, malformed lines, mixed intensities, zero stamps,
--max-scans), the real logs in ../shared/data, and a digest of an output's messages to compare runs.

tests/import_digests.json holds the digests of the whole-run importer (before the streaming one) for these inputs;
`python tests/import_cases.py` writes them again (only to record a deliberate change of output)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from test_import_carmen import flaser, robotlaser, write
from test_import_rosbag import ODOM, SCAN, STORE2, _odom, _scan, messages, write_ros1, write_ros2

DIGESTS = Path(__file__).with_name("import_digests.json")


def rawlaser(ranges, t: float) -> str:
    r = " ".join(f"{v:g}" for v in ranges)
    return f"RAWLASER1 0 -1.5708 3.14159 0.0174533 8.0 0.01 0 {len(ranges)} {r} 0 {t:.6f} host {t:.6f}"


def odom_line(x: float, t: float) -> str:
    return f"ODOM {x} 0.5 0.1 0.2 0.0 0.0 {t:.6f} host {t:.6f}"


def synthetic_inputs(tmp: Path) -> dict[str, tuple[Path, list[str]]]:
    """{case: (input, extra CLI arguments)}, written under `tmp`."""
    out: dict[str, tuple[Path, list[str]]] = {}
    beams = [1.0 + 0.01 * k for k in range(178)] + [81.9, 51.0]
    lines = [flaser([b + 0.001 * i for b in beams], 100.0 + 0.2 * i, pose=(0.1 * i, 0, 0.01 * i)) for i in range(30)]
    out["flaser"] = write(tmp, "flaser.log", ["PARAM robot_front_laser_max 50"] + lines), []
    out["flaser_gz_malformed"] = (
        write(tmp, "flaser.log.gz", lines[:7] + ["FLASER 3 1 2", "@@@", "ODOM x"] + lines[7:], gz=True),
        [],
    )
    out["flaser_max_scans"] = out["flaser"][0], ["--max-scans", "11"]
    back = [flaser(beams, 100.0 + 0.2 * i - (0.5 if i == 9 else 0.0)) for i in range(40)]
    out["flaser_repaired"] = write(tmp, "back.log", back), []
    out["flaser_synthesised"] = write(tmp, "synth.log", [flaser(beams, 1.13486e9) for _ in range(12)]), []
    out["flaser_flipped"] = write(tmp, "flip.log", ["PARAM laser_front_laser_flipped on"] + lines[:9]), []
    out["flaser_odd_beams"] = (
        write(tmp, "odd.log", [flaser([2.0 + 0.1 * k for k in range(11)], 5.0 + i) for i in range(6)]),
        [],
    )
    raw = []
    for i in range(25):
        raw.append(odom_line(0.1 * i, 50.0 + 0.1 * i - 0.03))
        raw.append(rawlaser([1.0 + 0.1 * ((i + k) % 7) for k in range(181)] + [], 50.0 + 0.1 * i))
    raw.append(odom_line(9.0, 60.0))
    out["rawlaser_odom"] = write(tmp, "raw.log", raw), []
    out["rawlaser_odom_max_scans"] = out["rawlaser_odom"][0], ["--max-scans", "7", "--topic", "RAWLASER1"]
    robot = [
        robotlaser([2.0 + 0.01 * ((i * k) % 13) for k in range(90)], 7.0 + i, rem=[0.5] * 90 if i % 3 else ())
        for i in range(14)
    ]
    out["robotlaser_g2o"] = write(tmp, "k.g2o", ["VERTEX_SE2 0 0 0 0"] + robot), []
    two = [ln for i in range(10) for ln in (flaser(beams, 10.0 + i), flaser(beams[:90], 10.05 + i, name="RLASER"))]
    out["two_lasers_topic"] = write(tmp, "two.log", two), ["--topic", "RLASER"]
    out["two_lasers_topic_max"] = out["two_lasers_topic"][0], ["--topic", "FLASER", "--max-scans", "4"]
    msgs = messages(n_scans=12, zero_stamp_at=3)
    out["ros1"] = write_ros1(tmp / "b.bag", msgs), ["--topic", "/front"]
    out["ros1_max_scans"] = out["ros1"][0], ["--topic", "/rear", "--max-scans", "5"]
    out["ros2_sqlite"] = write_ros2(tmp / "r2", msgs, "sqlite3"), ["--topic", "/front"]
    folder = write_ros2(tmp / "r2m", msgs)
    out["ros2_mcap"] = folder, ["--topic", "/rear"]
    out["mcap_file"] = next(folder.glob("*.mcap")), ["--topic", "/front"]
    out["mcap_file_max_scans"] = out["mcap_file"][0], ["--topic", "/front", "--max-scans", "4"]
    mixed = []
    for i in range(9):
        t = 2_000_000_000 + i * 50_000_000
        mixed.append(("/scan", SCAN, t, lambda s, t=t, i=i: _scan(s, t, 6, "laser", 1.0 + i, i % 4 != 1)))
        mixed.append(("/odom", ODOM, t + 7, lambda s, t=t, i=i: _odom(s, t + 7, 0.2 * i, 0.0)))
    out["ros1_mixed_intensities"] = write_ros1(tmp / "mixed.bag", mixed), []
    mfolder = write_ros2(tmp / "mixed2", mixed)
    out["mcap_mixed_intensities"] = next(mfolder.glob("*.mcap")), []
    assert STORE2 is not None
    return out


def shared_inputs(root: Path) -> dict[str, tuple[Path, list[str]]]:
    """{case: (input, extra CLI arguments)} of the real logs under ../shared/data (`root`)."""
    out = {f"carmen/{p.name}": (p, []) for p in sorted((root / "carmen").glob("*.log.gz"))}
    out["killian"] = root / "killian" / "killian.g2o.gz", []
    for p in sorted((root / "legtracker").glob("*.bag")):
        if p.name.startswith("positive"):
            out[f"legtracker/{p.name}"] = p, ["--topic", "/training_scan"]
        elif p.name.startswith("negative"):
            for t in ("/left_scan", "/rear_scan", "/right_scan"):
                out[f"legtracker/{p.name}{t}"] = p, ["--topic", t]
        else:
            out[f"legtracker/{p.name}"] = p, []
    out["carmen/intel-corrected.log.gz --max-scans 300"] = (
        root / "carmen" / "intel-corrected.log.gz",
        ["--max-scans", "300"],
    )
    return out


def digest(out: Path, src: Path) -> str:
    """SHA-256 of an output's channels, messages (topic, log time, payload, in file order) and metadata
    (less the tool version, command line and input hashes; the input's path as <src>)."""
    from datmo_cli.logs import mcapio

    h = hashlib.sha256()
    log = mcapio.LogContents(path=out)
    for topic, stamp, payload in mcapio.iter_messages(out, None, log):
        h.update(f"{topic} {stamp} ".encode() + hashlib.sha256(payload).digest())
    for ch in sorted(log.channels.values(), key=lambda c: c.id):
        h.update(
            repr(
                (
                    ch.id,
                    ch.topic,
                    ch.msgtype,
                    ch.message_encoding,
                    ch.schema_encoding,
                    ch.schema_data,
                    sorted(ch.metadata.items()),
                    ch.count,
                )
            ).encode()
        )
    for name in sorted(log.metadata):
        if name in ("datmo", "datmo.inputs"):
            continue
        items = sorted((k, v.replace(str(src), "<src>")) for k, v in log.metadata[name].items())
        h.update(repr((name, items)).encode())
    return h.hexdigest()


def import_digest(src: Path, extra: list[str], out: Path) -> tuple[int, str, str]:
    """(exit code, stderr with <src> for the input's path, digest or "") of `datmo import SRC -o OUT EXTRA`."""
    from click.testing import CliRunner

    from datmo_cli.cli import cli

    result = CliRunner().invoke(cli, ["import", str(src), "-o", str(out), "--force", *extra])
    text = result.output.replace(str(src), "<src>").replace(str(out), "<out>")
    return result.exit_code, text, digest(out, src) if result.exit_code == 0 else ""


SIMULATE_CASES = {
    "hall": ["--scene", "hall", "--duration", "110"],
    "patrol": ["--scene", "patrol", "--duration", "9", "--rate", "10"],
    "crowd": [
        "--scene",
        "crowd",
        "--people",
        "4",
        "--seed",
        "2",
        "--duration",
        "6",
        "--angle",
        "100",
        "--resolution",
        "0.25",
        "--range",
        "80",
    ],
}


def simulate_digest(args: list[str], out: Path) -> tuple[int, str, str]:
    """(exit code, output, digest) of `datmo simulate ARGS -o OUT`."""
    from click.testing import CliRunner

    from datmo_cli.cli import cli

    result = CliRunner().invoke(cli, ["simulate", *args, "-o", str(out), "--force"])
    text = result.output.replace(str(out), "<out>")
    return result.exit_code, text, digest(out, out) if result.exit_code == 0 else ""


if __name__ == "__main__":
    import sys
    import tempfile

    sys.path.insert(0, str(Path(__file__).parent))
    root = Path(__file__).resolve().parents[2] / "shared" / "data"
    with tempfile.TemporaryDirectory() as tmp:
        cases = synthetic_inputs(Path(tmp)) | shared_inputs(root)
        ref = {}
        for name, (src, extra) in cases.items():
            code, text, dig = import_digest(src, extra, Path(tmp) / "out.mcap")
            ref[name] = {"exit_code": code, "output": text, "digest": dig}
            print(name, code, dig[:12], text.strip().splitlines()[-1][:100])
        for name, args in SIMULATE_CASES.items():
            code, text, dig = simulate_digest(args, Path(tmp) / "sim.mcap")
            ref[f"simulate/{name}"] = {"exit_code": code, "output": text, "digest": dig}
            print(name, code, dig[:12], text.strip())
    DIGESTS.write_text(json.dumps(ref, indent=1, sort_keys=True) + "\n")
