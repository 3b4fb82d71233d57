"""`datmo run`'s outputs on every sample log, message for message (tests/run_cases.py, markers and the tracks'
covariance aside): what tests/run_digests.json records, on any machine (fingerprints: floats within a stated
tolerance, everything else exact), and bit for bit the same whatever the perception threads (--threads) and the
streaming block size. Speed work must leave these alone; a deliberate change of the tracker or of perception
writes them again (`make run-digests`) with the reason in its commit."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from run_cases import DIGESTS, FLOAT_RTOL, differences, digests, fingerprints, run_outputs, sample_logs

from datmo_cli.passes import pipeline
from datmo_cli.passes.pipeline import process_file

pytestmark = pytest.mark.cli


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> dict[str, dict]:
    out = run_outputs(tmp_path_factory.mktemp("threads1"), "--threads", "1")
    return {name: digests(path) for name, path in out.items()}


def test_every_sample_log_is_covered(reference):
    assert set(reference) == {p.name for p in sample_logs()} and len(reference) >= 6
    for name, channels in reference.items():
        assert "/datmo/tracks" in channels and "/datmo/features" in channels, name
        assert not any(t.startswith("/datmo/markers/") for t in channels), name


@pytest.fixture(scope="module")
def outputs(tmp_path_factory) -> dict[str, Path]:
    return run_outputs(tmp_path_factory.mktemp("fingerprints"), "--threads", "1")


def test_outputs_match_the_stored_fingerprints(outputs):
    stored = json.loads(DIGESTS.read_text())
    assert set(stored) == set(outputs)
    for name, path in sorted(outputs.items()):
        found = differences(stored[name], fingerprints(path))
        assert not found, (
            f"{name}: datmo run's output differs from {DIGESTS.name}: " + "; ".join(found) + ". If the change is "
            "meant (a tracker or perception change), run `make run-digests` and give the reason in the commit"
        )


def _float_fields_moved(decode, seed: int):
    """cdr.decode whose float fields come back moved one unit in the last place (float32), up or down at random:
    what rounding differently in the last bits gives."""
    rng = np.random.default_rng(seed)

    def moved(msgtype, payload):
        msg = decode(msgtype, payload)
        for key, value in msg.items():
            if isinstance(value, np.ndarray) and value.dtype.names:
                value = msg[key] = value.copy()
                for f in value.dtype.names:
                    if value.dtype[f].kind == "f":
                        v = value[f]
                        value[f] = np.nextafter(v, np.where(rng.random(v.shape) < 0.5, -np.inf, np.inf)).astype(v.dtype)
            elif isinstance(value, float):
                msg[key] = float(np.nextafter(np.float32(value), np.float32(np.inf)))
        return msg

    return moved


@pytest.mark.slow
def test_fingerprints_let_last_bit_rounding_pass_and_catch_a_one_percent_change(outputs, tmp_path, monkeypatch):
    """The stored comparison fails for datmo's changes, not for rounding: every float of every output moved one
    unit in the last place keeps its fingerprint; a 1% change of one tracking parameter does not."""
    from datmo_cli.logs import cdr

    here = {name: fingerprints(path) for name, path in outputs.items()}
    monkeypatch.setattr(cdr, "decode", _float_fields_moved(cdr.decode, 1))
    for name, path in outputs.items():
        assert not differences(here[name], fingerprints(path)), name
    monkeypatch.undo()

    config = tmp_path / "noise.toml"
    config.write_text("[track]\nmeasurement_noise = 0.0505\n")
    changed = run_outputs(tmp_path / "changed", "--threads", "1", "--config", str(config))
    caught = {name: differences(here[name], fingerprints(path)) for name, path in changed.items()}
    assert all(any("/datmo/tracks" in line for line in lines) for lines in caught.values()), caught


NUMPY_SIMD_MATH = ("sin", "cos", "tan", "arcsin", "arccos", "arctan", "arctan2", "exp", "expm1", "log", "log1p")


@pytest.mark.slow
def test_numpy_math_that_rounds_otherwise_changes_no_bit_of_any_output(reference, tmp_path, monkeypatch):
    """numpy's float64 sin, cos, arctan2 and kin round by the CPU's SIMD code (AVX-512 or not). With each of them
    replaced by one that rounds every result one unit in the last place up or down, every output is still bit for
    bit the same: no such result reaches an output (libm.py; tests/test_libm.py keeps new calls out)."""
    import numba.np.npyimpl  # noqa: F401  (numba's ufunc tables read numpy's ufuncs once, before they are replaced)

    for i, name in enumerate(NUMPY_SIMD_MATH):
        ufunc = getattr(np, name)
        rng = np.random.default_rng(i)

        def rounded_otherwise(*args, _u=ufunc, _rng=rng, **kwargs):
            out = np.asarray(_u(*args, **kwargs))
            return np.nextafter(out, np.where(_rng.random(out.shape) < 0.5, -np.inf, np.inf))

        monkeypatch.setattr(np, name, rounded_otherwise)
    out = run_outputs(tmp_path, "--threads", "1")
    monkeypatch.undo()
    assert {name: digests(path) for name, path in out.items()} == reference


def test_the_float_comparison_has_the_stated_tolerance():
    a = {"/t": {"messages": 1, "exact": "x", "floats": {"f": [10.0, 1.0, 1.0, 100.0, 3]}}}
    inside = {"/t": {"messages": 1, "exact": "x", "floats": {"f": [10.0 + 0.9e-4, 1.0, 1.0, 100.0, 3]}}}
    outside = {"/t": {"messages": 1, "exact": "x", "floats": {"f": [10.0 + 1.1e-4, 1.0, 1.0, 100.0, 3]}}}
    assert FLOAT_RTOL == 1e-6 and differences(a, inside) == []
    assert differences(a, outside) == ["/t f: sums differ by 0.00011 (tolerance 0.0001)"]
    assert differences(a, {"/t": {**a["/t"], "exact": "y"}}) == ["/t: times, counts, integer or text fields differ"]


def test_same_outputs_with_two_threads(reference, tmp_path):
    out = run_outputs(tmp_path, "--threads", "2")
    assert {name: digests(path) for name, path in out.items()} == reference


@pytest.mark.parametrize("block", [7, 100])
def test_same_outputs_for_any_block_size(reference, tmp_path, block):
    for log in sample_logs():
        out = tmp_path / log.name
        process_file(log, out, force=True, block_scans=block)
        assert digests(out) == reference[log.name], (log.name, block)


@pytest.mark.parametrize("ahead", [1, pipeline.PERCEIVE_AHEAD, 5])
def test_same_outputs_with_the_next_blocks_perceived_on_their_own_thread(reference, tmp_path, monkeypatch, ahead):
    """Two threads or more: RunStages.pipelined perceives blocks k + 1 .. k + ahead on a thread beside the
    tracking of block k; on many small blocks, whatever the machine's cores, the outputs stay the same."""
    from datmo_cli.perception import threads

    monkeypatch.setattr(pipeline, "PERCEIVE_AHEAD", ahead)
    monkeypatch.setattr(threads, "available", lambda: 2)
    monkeypatch.setattr(threads, "_DEFAULT", 2)
    for log in sample_logs():
        out = tmp_path / log.name
        process_file(log, out, force=True, block_scans=50)
        assert digests(out) == reference[log.name], log.name
