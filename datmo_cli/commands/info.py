"""`datmo info`: what a log holds."""

from __future__ import annotations

import json
from pathlib import Path

import click

from .types import quiet_option


def describe(path: Path) -> dict:
    """A JSON-ready description of a log: channels, scan geometry and rate, provenance metadata."""
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
        import warnings

        warnings.warn(several, stacklevel=2)
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


def _print_rich(info: dict) -> None:
    from ..base.progress import console as make_console
    from ..base.progress import table as make_table
    from ..base.text import markup

    console = make_console()
    console.print(
        f"[bold]{markup(info['file'])}[/]  {info['size_bytes'] / 1e6:.2f} MB, {info['duration_s']:.1f} s, "
        f"profile {markup(info['profile'] or '-')}, written by {markup(info['library'] or '-')}"
    )
    if info["truncated"]:
        console.print("[yellow]truncated: only complete chunks were read[/]")
    if info["corrupt_chunks"]:
        console.print(
            f"[yellow]corrupt: {info['corrupt_chunks']} chunk(s) ({info['corrupt_bytes']:,} bytes) failed "
            "their CRC or did not decompress and were skipped; counts and scans leave them out[/]"
        )
    table = make_table(console, title="Channels", title_justify="left")
    for col in ("topic", "type", "encoding", "messages"):
        table.add_column(col, justify="right" if col == "messages" else "left")
    for c in info["channels"]:
        table.add_row(c["topic"], c["type"], c["encoding"], f"{c['messages']:,}")
    console.print(table)
    scan = info["scan"]
    if scan:
        t = make_table(console, title="Scans (/scan)", title_justify="left", show_header=False)
        t.add_column("what")
        t.add_column("value")
        rows = [
            ("scans", f"{scan['scans']:,}"),
            ("rate", f"{scan['rate_hz']:.2f} Hz" if scan["rate_hz"] else "-"),
            ("gaps (> 1.5 periods)", str(scan["gaps"])),
            ("beams", str(scan["beams"])),
            ("field of view", f"{scan['fov_deg']:.2f}° ({scan['angle_min_deg']:.2f}° to {scan['angle_max_deg']:.2f}°)"),
            ("resolution", f"{scan['resolution_deg']:.3f}°"),
            ("range limits", f"{scan['range_min_m']:g} m to {scan['range_max_m']:g} m"),
            ("frame", scan["frame_id"]),
            ("intensities", "yes" if scan["intensities"] else "no"),
            ("valid returns", f"{100 * scan['valid_returns']:.1f}%"),
        ]
        for r in rows:
            t.add_row(*r)
        console.print(t)
    if info["metadata"]:
        m = make_table(console, title="Provenance and metadata", title_justify="left")
        m.add_column("record")
        m.add_column("key")
        m.add_column("value", overflow="fold")
        for name, data in info["metadata"].items():
            for i, (k, v) in enumerate(data.items()):
                m.add_row(name if i == 0 else "", k, v)
        console.print(m)


@click.command(name="info")
@click.argument("log", type=click.Path(path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print JSON for scripts instead of tables.")
@quiet_option
def command(log: Path, as_json: bool) -> None:
    """Show LOG's channels, scan geometry, rate and provenance.

    Example: datmo info sample_logs/hall.mcap --json
    """
    import warnings

    info = describe(log)
    if not any(c["topic"] == "/scan" and c["messages"] for c in info["channels"]):
        warnings.warn(f"{log}: no scans on /scan (it holds {len(info['channels'])} other channel(s))", stacklevel=1)
    if as_json:
        click.echo(json.dumps(info, indent=2))
    else:
        _print_rich(info)
