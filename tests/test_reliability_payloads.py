"""Damage a CRC cannot see is an input error: a datmo_msgs payload that is not what its
channel says, in a sound chunk (written so, or damaged before the chunk's CRC was computed), and a leg model of
the wrong types or with NaN in it, once ended in exit 70 with a traceback class. Each is exit 1, one line naming
the file (and the topic and message)."""

from __future__ import annotations

import json
import random

import numpy as np
import pytest
from click.testing import CliRunner
from fuzzing import tally

from datmo_cli.cli import cli
from datmo_cli.logs import cdr, mcapio, types

pytestmark = pytest.mark.cli


def run_cli(*args) -> tuple[int, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    return result.exit_code, result.stderr


def one_error(code: int, err: str, *texts: str) -> None:
    lines = err.splitlines()
    assert code == 1 and len(lines) == 1 and lines[0].startswith("datmo: error: "), err
    for text in texts:
        assert text in lines[0], (text, lines[0])


@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    """The synthetic processed log (scans, features, landmarks, tracks, ground truth) and the hall sample log
    segmented (/datmo/segments)."""
    import synthetic_logs as syn

    folder = tmp_path_factory.mktemp("payloads")
    path = folder / "processed.mcap"
    syn.write(path)
    segmented = folder / "segmented.mcap"
    from conftest import SAMPLE_LOGS

    assert CliRunner().invoke(cli, ["segment", str(SAMPLE_LOGS / "hall.mcap"), "-o", str(segmented)]).exit_code == 0
    return path, segmented


DAMAGE = {
    "cut": lambda p: p[: len(p) // 2],
    "bytes after": lambda p: p + b"\0" * 8,
    "big endian": lambda p: b"\x00\x00" + p[2:],
    "the frame's length": lambda p: p[:12] + b"\xff\xff\xff\x0f" + p[16:],
}  # after the CDR header and stamp


def rewrite(src, dst, topic: str, damage, k: int = 7) -> None:
    """`src` copied to `dst` (sound chunks, fresh CRCs) with message `k` of `topic` damaged."""
    log = mcapio.read_log(src, topics=None)
    with mcapio.LogWriter(dst, force=True) as w:
        for t, cid in w.copy_channels(log).items():
            stamps, payloads = log.messages[t]
            payloads = list(payloads)
            if t == topic:
                payloads[k] = damage(payloads[k])
            w.write_ids(cid, stamps, payloads)


CASES = [
    (mcapio.TOPIC_TRACKS, "report", types.TRACKS),
    (mcapio.TOPIC_TRACKS, "evaluate", types.TRACKS),
    (mcapio.TOPIC_FEATURES, "report", types.FEATURES),
    (mcapio.TOPIC_FEATURES, "track", types.FEATURES),
    (mcapio.TOPIC_GROUND_TRUTH, "evaluate", types.GROUND_TRUTH),
    (mcapio.TOPIC_SEGMENTS, "features", types.SEGMENTS),
]


@pytest.mark.parametrize("damage", list(DAMAGE))
@pytest.mark.parametrize("topic, command, msgtype", CASES)
def test_a_damaged_datmo_payload_in_a_sound_chunk_is_one_line(tmp_path, processed, topic, command, msgtype, damage):
    src = processed[1] if topic == mcapio.TOPIC_SEGMENTS else processed[0]
    bad = tmp_path / "bad.mcap"
    rewrite(src, bad, topic, DAMAGE[damage])
    out = [] if command in ("report", "evaluate") else ["-o", tmp_path / "out.mcap"]
    code, err = run_cli(command, bad, *out)
    one_error(code, err, f"{bad}: bad message on {topic}: message 7: {msgtype}")
    assert not (tmp_path / "out.mcap").exists()


def test_given_segments_no_scan_could_have_name_the_file(tmp_path, processed):
    def beyond(p: bytes) -> bytes:
        m = cdr.decode(types.SEGMENTS, p)
        start, end = np.array(m["start"]), np.array(m["end"])
        start[0], end[0] = 10**6, 10**6 + 5
        return cdr.encode(
            types.SEGMENTS, {"stamp_ns": m["stamp_ns"], "frame_id": m["frame_id"], "start": start, "end": end}
        )

    bad = tmp_path / "bad.mcap"
    rewrite(processed[1], bad, mcapio.TOPIC_SEGMENTS, beyond)
    code, err = run_cli("features", bad, "-o", tmp_path / "out.mcap")
    one_error(code, err, f"{bad}: {mcapio.TOPIC_SEGMENTS}: segment [")


@pytest.mark.parametrize("msgtype", [types.TRACKS, types.FEATURES, types.LANDMARKS, types.GROUND_TRUTH, types.SEGMENTS])
def test_fuzz_datmo_payloads_decode_or_say_why(processed, msgtype):
    """Flipped, cut and extended payloads of every datmo_msgs type: cdr.decode gives a message or DecodeError,
    never another exception (which the CLI would call an internal error)."""
    src = processed[1] if msgtype == types.SEGMENTS else processed[0]
    topic = {
        types.TRACKS: mcapio.TOPIC_TRACKS,
        types.FEATURES: mcapio.TOPIC_FEATURES,
        types.LANDMARKS: mcapio.TOPIC_LANDMARKS,
        types.GROUND_TRUTH: mcapio.TOPIC_GROUND_TRUTH,
        types.SEGMENTS: mcapio.TOPIC_SEGMENTS,
    }[msgtype]
    _, payloads = mcapio.read_messages(src, topic)
    rng = random.Random(msgtype)
    for case in range(80):
        p = bytearray(payloads[rng.randrange(len(payloads))])
        how = case % 3
        if how == 0:
            for _ in range(rng.randint(1, 4)):
                p[rng.randrange(len(p))] ^= rng.randrange(1, 256)
        elif how == 1:
            p = p[: rng.randrange(len(p))]
        else:
            p += bytes(rng.randrange(256) for _ in range(rng.randint(1, 40)))
        try:
            try:
                cdr.decode(msgtype, bytes(p))
            except cdr.DecodeError:
                pass
        except BaseException:
            tally("datmo payload fuzz", failed=True)
            raise
        tally("datmo payload fuzz")


# ----------------------------------------------------------------------------------- corrupt leg models


def bad_model(path, kind: str) -> None:
    from datmo_cli.perception.leg_model import DEFAULT_MODEL_PATH

    z = dict(np.load(DEFAULT_MODEL_PATH))
    prov = json.loads(str(z["provenance"]))
    if kind == "provenance a list":
        z["provenance"] = np.str_(json.dumps([1, 2]))
    elif kind == "provenance a number":
        z["provenance"] = np.str_("5")
    elif kind == "provenance clusters a string":
        z["provenance"] = np.str_(json.dumps({**prov, "clusters": "gap"}))
    elif kind == "provenance gap not a number":
        z["provenance"] = np.str_(json.dumps({**prov, "clusters": {"method": "gap", "gap": "wide"}}))
    elif kind == "NaN feature index":
        f = z["feature"].astype(float)
        f[5] = np.nan
        z["feature"] = f
    elif kind == "NaN threshold":
        t = z["threshold"].copy()
        t[np.flatnonzero(z["feature"] >= 0)[0]] = np.nan
        z["threshold"] = t
    elif kind == "kind an array":
        z["kind"] = np.array(["forest", "forest"])
    elif kind == "names numbers":
        z["feature_names"] = np.arange(len(z["feature_names"]))
    np.savez_compressed(path, **z)


@pytest.mark.parametrize(
    "kind",
    [
        "provenance a list",
        "provenance a number",
        "provenance clusters a string",
        "provenance gap not a number",
        "NaN feature index",
        "NaN threshold",
        "kind an array",
        "names numbers",
    ],
)
def test_a_corrupt_leg_model_is_one_line(tmp_path, kind):
    from datmo_cli.perception.leg_model import LegModel

    model = tmp_path / "bad.npz"
    bad_model(model, kind)
    with pytest.raises(Exception) as exc:
        LegModel.load(model)
    assert type(exc.value).__name__ == "InputError" and str(exc.value).startswith(f"{model}: "), exc.value
    from conftest import SAMPLE_LOGS

    code, err = run_cli("features", SAMPLE_LOGS / "hall.mcap", "-o", tmp_path / "out.mcap", "--leg-model", model)
    one_error(code, err, f"{model}: ")
