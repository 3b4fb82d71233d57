"""Digests of `datmo run`'s outputs on every sample log, message for message, to guard speed work: a change
that is only meant to make datmo faster or its outputs smaller must leave them as they are.

A digest is taken per channel: the SHA-256 of its messages in file order, each its log time and its content.
datmo_msgs messages are decoded and their fields hashed (so a change of encoding alone does not count), less
the tracks' covariance (stored only with --covariance); other messages (the input's copies, /odom, /tf) by
their bytes. The Foxglove markers (/datmo/markers/*, stored only with --markers) are left out.

tests/run_digests.json holds the digests of every sample log's output with the defaults. When a change of the
tracker or of perception changes the outputs on purpose, write them again and say why in the commit:

    make run-digests            # or: .venv/bin/python tests/run_cases.py
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SAMPLE_LOGS = ROOT / "sample_logs"
DIGESTS = Path(__file__).with_name("run_digests.json")
LEFT_OUT_FIELDS = {"datmo_msgs/msg/Tracks": {"tracks": ("covariance",)}}


def sample_logs() -> list[Path]:
    return sorted(SAMPLE_LOGS.glob("*.mcap"))


def left_out(topic: str) -> bool:
    """Channels the digests leave out: the markers."""
    return topic.startswith("/datmo/markers/")


def _canonical(value: object, drop: tuple[str, ...] = ()) -> bytes:
    """Bytes standing for a decoded field: numpy arrays by dtype and data (structured ones less `drop`)."""
    if isinstance(value, np.ndarray):
        if value.dtype.names:
            keep = [n for n in value.dtype.names if n not in drop]
            value = np.lib.recfunctions.repack_fields(value[keep])
        value = np.ascontiguousarray(value)
        return repr(value.dtype.descr).encode() + repr(value.shape).encode() + value.tobytes()
    if isinstance(value, dict):
        return b"{" + b",".join(k.encode() + b":" + _canonical(v) for k, v in sorted(value.items())) + b"}"
    return repr(value).encode()


def message_digest(msgtype: str, payload: bytes) -> bytes:
    """SHA-256 of one message's content (see the module docstring)."""
    from datmo_cli.log import cdr

    if not msgtype.startswith("datmo_msgs/"):
        return hashlib.sha256(payload).digest()
    drops = LEFT_OUT_FIELDS.get(msgtype, {})
    msg = cdr.decode(msgtype, payload)
    h = hashlib.sha256()
    for name in sorted(msg):
        h.update(name.encode() + b"=" + _canonical(msg[name], drops.get(name, ())) + b";")
    return h.digest()


def digests(path: Path) -> dict[str, dict]:
    """{topic: {"messages": count, "sha256": hex}} of the log at `path`, markers left out."""
    import numpy.lib.recfunctions  # noqa: F401  (np.lib.recfunctions)

    from datmo_cli.log import mcapio

    contents = mcapio.LogContents(path=path)
    hashes: dict[str, hashlib._Hash] = {}
    counts: dict[str, int] = {}
    types: dict[str, str] = {}
    for topic, stamp, payload in mcapio.iter_messages(path, None, contents):
        if left_out(topic):
            continue
        if topic not in types:
            types[topic] = next(c.msgtype for c in contents.channels.values() if c.topic == topic)
            hashes[topic] = hashlib.sha256()
            counts[topic] = 0
        hashes[topic].update(f"{stamp} ".encode() + message_digest(types[topic], payload))
        counts[topic] += 1
    return {t: {"messages": counts[t], "sha256": hashes[t].hexdigest()} for t in sorted(hashes)}


def run_outputs(out_dir: Path, *extra: str) -> dict[str, Path]:
    """`datmo run` of every sample log into `out_dir` (one process, --no-report, `extra` options):
    {log name: output}."""
    from click.testing import CliRunner

    from datmo_cli.cli import cli

    logs = sample_logs()
    result = CliRunner().invoke(
        cli, ["run", *map(str, logs), "-o", str(out_dir), "--force", "--jobs", "1", "--no-report", "-q", *extra]
    )
    if result.exit_code != 0:
        raise RuntimeError(f"datmo run failed ({result.exit_code}): {result.output}")
    return {log.name: out_dir / log.name for log in logs}


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        ref = {name: digests(out) for name, out in run_outputs(Path(tmp), "--threads", "1").items()}
    DIGESTS.write_text(json.dumps(ref, indent=1, sort_keys=True) + "\n")
    print(f"{DIGESTS}: digests of {len(ref)} outputs written")
