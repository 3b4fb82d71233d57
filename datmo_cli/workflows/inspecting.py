"""`datmo info` and `datmo config` as calls (datmo_cli.api.info, api.config): what a log holds (its channels, scan
geometry and rate, provenance), and the effective configuration as TOML that datmo reads back identically. The
commands keep what they print (tables, JSON, the TOML on stdout)."""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig
    from . import Config


def info(path: str | os.PathLike) -> dict:
    """`datmo info LOG --json`: a JSON-ready description of the log at `path`: file, size_bytes, profile,
    library, truncated, corrupt_chunks, corrupt_bytes, start_ns, end_ns, duration_s, channels (topic, type,
    encoding, messages), metadata (the provenance records), and scan: scans, rate_hz, gaps (> 1.5 periods),
    beams, fov_deg, resolution_deg, angle_min_deg, angle_max_deg (sensor frame, counter-clockwise from x
    forward), range_min_m, range_max_m, frame_id, intensities, valid_returns (a fraction), or None without
    /scan. A log without scans is described with a warning; InputError for a file that is not a log."""
    path = Path(path)
    described = describe(path)
    if not any(c["topic"] == "/scan" and c["messages"] for c in described["channels"]):
        warnings.warn(
            f"{path}: no scans on /scan (it holds {len(described['channels'])} other channel(s))", stacklevel=2
        )
    return described


def describe(path: Path) -> dict:
    """A JSON-ready description of a log: channels, scan geometry and rate, provenance metadata (info's)."""
    import numpy as np

    from ..logs import mcapio

    log = mcapio.read_log(path, topics=[mcapio.TOPIC_SCAN])
    duration = (log.end_ns - log.start_ns) / 1e9
    out: dict = {
        "file": str(path),
        "size_bytes": log.size,
        "profile": log.profile,
        "library": log.library,
        "truncated": log.truncated,
        "corrupt_chunks": log.corrupt_chunks,
        "corrupt_bytes": log.corrupt_bytes,
        "start_ns": log.start_ns,
        "end_ns": log.end_ns,
        "duration_s": round(duration, 6),
        "channels": [
            {"topic": c.topic, "type": c.msgtype, "encoding": c.message_encoding, "messages": c.count}
            for c in sorted(log.channels.values(), key=lambda c: c.topic)
        ],
        "metadata": log.metadata,
        "scan": None,
    }
    several = mcapio.several_channels(log, mcapio.TOPIC_SCAN)
    if several:  # info still shows the channels; the stage commands refuse the log
        warnings.warn(several, stacklevel=3)
    elif log.has(mcapio.TOPIC_SCAN):
        run = mcapio.run_from_log(log)
        g = run.geometry
        dt = np.diff(run.stamps) / 1e9
        rate = float(1 / np.median(dt)) if len(dt) and np.median(dt) > 0 else None
        gaps = int(np.sum(dt > 1.5 * np.median(dt))) if len(dt) else 0
        finite = np.isfinite(run.ranges)
        out["scan"] = {
            "scans": len(run),
            "rate_hz": round(rate, 3) if rate else None,
            "gaps": gaps,
            "beams": g.n_beams,
            "fov_deg": round(float(np.degrees(g.angle_increment * (g.n_beams - 1))), 4),
            "resolution_deg": round(float(np.degrees(g.angle_increment)), 4),
            "angle_min_deg": round(float(np.degrees(g.angle_min)), 4),
            "angle_max_deg": round(float(np.degrees(g.angle_max)), 4),
            "range_min_m": round(g.range_min, 4),
            "range_max_m": round(g.range_max, 4),
            "frame_id": g.frame_id,
            "intensities": bool(run.intensities.shape[1]),
            "valid_returns": round(float(finite.mean()), 4) if finite.size else 0.0,
        }
    return out


def config(
    config: Config = None,
    output: str | os.PathLike | None = None,
    *,
    force: bool = False,
    source: str | os.PathLike | None = None,
) -> str:
    """`datmo config`: the effective configuration as TOML: every [features] and [track] parameter with its
    value, each followed by a comment saying where it came from (the defaults, or the file) and its unit; datmo
    reads it back to the same parameters. `config` as api.process takes it (a TOML file is also the source the
    comments name); `source`: the file a DatmoConfig given was read from (None: none). With `output`, the
    TOML is also written there (an existing file only with `force`; the config files read are refused)."""
    from ..passes.config import DatmoConfig, to_toml
    from . import as_config

    if source is None and config is not None and not isinstance(config, (DatmoConfig, dict)):
        source = config
    path = Path(source) if source is not None else None
    cfg = as_config(config)
    header = (
        f"datmo's effective configuration: the defaults, overridden by {path}"
        if path is not None
        else "datmo's effective configuration: the defaults (no config file)"
    )
    text = to_toml(cfg.to_dict(), sources(cfg, path), header)
    if output is not None:
        from ..base.outputs import atomic_output

        read = [p for p in (path, cfg.features.leg_model) if p]  # its inputs: refused as outputs, even with force
        with atomic_output(Path(output), force=force, mode="w", inputs=read, what="config") as f:
            f.write(text)
    return text


def sources(cfg: DatmoConfig, config: Path | None) -> dict[str, dict[str, str]]:
    """Where each value of `cfg` comes from ('default' or the config file's name) with its unit, by section
    and key (a parameter written outside its home section, as [track] d_max, counts for its home)."""
    from ..passes.config import BOUNDS, SECTIONS, STAGES, read_tables, same_as

    tables = read_tables(config) if config is not None else {}
    given = {s: set(tables.get(s, ())) for s in STAGES}
    for s in STAGES:
        for name, key in same_as(SECTIONS[s]).items():
            home, _, home_key = key.partition(".")
            if name in given[s]:
                given[home].add(home_key)
    out = {}
    for stage, table in cfg.to_dict().items():
        bounds = BOUNDS[stage]
        out[stage] = {
            key: (f"from {config}" if key in given[stage] else "default")
            + (f"; {bounds[key].unit}" if key in bounds and bounds[key].unit else "")
            for key in table
        }
    return out
