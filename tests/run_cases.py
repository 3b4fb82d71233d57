"""`datmo run`'s outputs on every sample log, message for message, to guard speed work: a change that is only
meant to make datmo faster or its outputs smaller must leave them as they are.

Two summaries per channel, both of its messages in file order. datmo_msgs messages are decoded (so a change of
encoding alone does not count), less the tracks' covariance (stored only with --covariance); other messages
(the input's copies, /odom, /tf) are taken by their bytes. The Foxglove markers (/datmo/markers/*, stored only
with --markers) are left out.

- `digests`: the SHA-256 of every message's log time and content, float bits included. Two runs on one machine
  (threads, block sizes) must give the same.
- `fingerprints`: what holds on every machine. Log times, counts, integer and text fields, and where floats are
  not finite, exactly (a SHA-256); every float field by four sums over its values in order (their sum, two sums
  weighted by fixed pseudo-random weights of the value's place, and the sum of magnitudes), which `differences`
  compares within FLOAT_RTOL of the sum of magnitudes. A value moved by rounding in the last bits (another CPU's
  SIMD code, another numpy) stays inside; a changed value, a swapped pair or a drift of the whole field does not.

tests/run_digests.json holds the fingerprints of every sample log's output with the defaults. When a change of
the tracker or of perception changes the outputs on purpose, write them again and say why in the commit:

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
    from datmo_cli.logs import cdr

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

    from datmo_cli.logs import mcapio

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


# a float field's sums may move by this share of its sum of magnitudes: a float32 value rounded one unit in the
# last place differently moves by 6e-8 of itself, so even every value of a field moved so stays 16x inside
FLOAT_RTOL = 1e-6


class _Fingerprint:
    """The fingerprint of one channel (module docstring), fed message by message."""

    def __init__(self) -> None:
        self.exact = hashlib.sha256()
        self.sums: dict[str, np.ndarray] = {}
        self.seen: dict[str, int] = {}
        self.messages = 0

    def add(self, stamp: int, msgtype: str, payload: bytes) -> None:
        from datmo_cli.logs import cdr

        self.messages += 1
        self.exact.update(f"@{stamp};".encode())
        if not msgtype.startswith("datmo_msgs/"):
            self.exact.update(hashlib.sha256(payload).digest())
            return
        drops = LEFT_OUT_FIELDS.get(msgtype, {})
        msg = cdr.decode(msgtype, payload)
        for name in sorted(msg):
            self._value(name, msg[name], drops.get(name, ()))

    def _value(self, name: str, value: object, drop: tuple[str, ...] = ()) -> None:
        if isinstance(value, np.ndarray) and value.dtype.names:
            self.exact.update(f"{name}#{value.shape}".encode())
            for field in value.dtype.names:
                if field not in drop:
                    self._value(f"{name}.{field}", np.ascontiguousarray(value[field]))
        elif isinstance(value, np.ndarray) and value.dtype.kind == "f" or isinstance(value, float):
            self._floats(name, np.asarray(value, np.float64).ravel())
        elif isinstance(value, np.ndarray):
            self.exact.update(f"{name}:{value.dtype.str}{value.shape}=".encode() + value.tobytes())
        elif isinstance(value, dict):
            for key in sorted(value):
                self._value(f"{name}.{key}", value[key])
        else:
            self.exact.update(f"{name}={value!r};".encode())

    def _floats(self, name: str, v: np.ndarray) -> None:
        bad = ~np.isfinite(v)
        if bad.any():
            self.exact.update(f"{name}!{np.flatnonzero(bad).tolist()}{v[bad].tolist()}".encode())
            v = np.where(bad, 0.0, v)
        first = self.seen.get(name, 0)
        place = np.arange(first, first + v.size, dtype=np.uint64)
        self.seen[name] = first + v.size
        w1 = ((place * np.uint64(2654435761)) % np.uint64(1 << 32)).astype(np.float64) / 2.0**32 - 0.5
        w2 = ((place * np.uint64(40503) + np.uint64(12345)) % np.uint64(1 << 16)).astype(np.float64) / 2.0**16 - 0.5
        sums = np.array([v.sum(), (v * w1).sum(), (v * w2).sum(), np.abs(v).sum()])
        self.sums[name] = self.sums.get(name, np.zeros(4)) + sums

    def result(self) -> dict:
        return {
            "messages": self.messages,
            "exact": self.exact.hexdigest(),
            "floats": {k: [float(x) for x in self.sums[k]] + [self.seen[k]] for k in sorted(self.sums)},
        }


def fingerprints(path: Path) -> dict[str, dict]:
    """{topic: {"messages", "exact", "floats": {field: [sum, weighted sum 1, weighted sum 2, sum of magnitudes,
    values]}}} of the log at `path`, markers left out (module docstring)."""
    from datmo_cli.logs import mcapio

    contents = mcapio.LogContents(path=path)
    found: dict[str, _Fingerprint] = {}
    types: dict[str, str] = {}
    for topic, stamp, payload in mcapio.iter_messages(path, None, contents):
        if left_out(topic):
            continue
        if topic not in found:
            types[topic] = next(c.msgtype for c in contents.channels.values() if c.topic == topic)
            found[topic] = _Fingerprint()
        found[topic].add(stamp, types[topic], payload)
    return {t: found[t].result() for t in sorted(found)}


def differences(stored: dict[str, dict], got: dict[str, dict], rtol: float = FLOAT_RTOL) -> list[str]:
    """What differs between two `fingerprints` of one log, a line each (empty: the same within rtol)."""
    out = []
    for topic in sorted(set(stored) | set(got)):
        a, b = stored.get(topic), got.get(topic)
        if a is None or b is None:
            out.append(f"{topic}: {'new' if a is None else 'missing'} channel")
            continue
        if a["messages"] != b["messages"]:
            out.append(f"{topic}: {b['messages']} messages, {a['messages']} stored")
        if a["exact"] != b["exact"]:
            out.append(f"{topic}: times, counts, integer or text fields differ")
        for field in sorted(set(a["floats"]) | set(b["floats"])):
            fa, fb = a["floats"].get(field), b["floats"].get(field)
            if fa is None or fb is None or fa[4] != fb[4]:
                out.append(f"{topic} {field}: {fb and fb[4]} values, {fa and fa[4]} stored")
                continue
            tol = rtol * max(fa[3], fb[3], 1e-30)
            worst = max(abs(x - y) for x, y in zip(fa[:4], fb[:4], strict=True))
            if worst > tol:
                out.append(f"{topic} {field}: sums differ by {worst:.3g} (tolerance {tol:.3g})")
    return out


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
        ref = {name: fingerprints(out) for name, out in run_outputs(Path(tmp), "--threads", "1").items()}
    DIGESTS.write_text(json.dumps(ref, indent=1, sort_keys=True) + "\n")
    print(f"{DIGESTS}: fingerprints of {len(ref)} outputs written")
