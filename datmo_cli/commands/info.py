"""`datmo info`: what a log holds: one call of datmo_cli.api.info (workflows.inspecting), printed as tables or JSON."""

from __future__ import annotations

import json
from pathlib import Path

import click

from .types import quiet_option


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
    from .. import api

    info = api.info(log)
    if as_json:
        click.echo(json.dumps(info, indent=2))
    else:
        _print_rich(info)
