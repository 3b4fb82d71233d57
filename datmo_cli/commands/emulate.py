"""`datmo emulate`: a virtual LMS200 on a pseudo-terminal, to test `datmo record` without hardware."""

from __future__ import annotations

import os
import signal
import threading
from pathlib import Path

import click

from ..base.bounds import OPTIONS
from .options import force_option, quiet_option
from .types import option

FAULT_HELP = (
    "Faults to inject, comma-separated: garbage:P (a burst of random bytes before a scan), crc:P (corrupt "
    "a scan's CRC), truncate:P (cut a scan short), drop:P (leave out one byte of a scan), with P the "
    "probability per scan telegram; disconnect:N (hang up after N scan telegrams); nak:N (answer the "
    "first N host commands with NAK). E.g. garbage:0.1,crc:0.05,disconnect:500."
)


@click.command(name="emulate")
@click.option(
    "--scene",
    metavar="NAME|PATH",
    default=None,
    help="Serve scans of a simulated scene (hall, corridor, crowd, static, patrol or a .toml) [default: hall].",
)
@click.option(
    "--log",
    "log_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Serve the scans of this log instead (repeated; beams mapped by angle onto the variant).",
)
@option(
    "--seed", bound=OPTIONS["seed"], default=0, show_default=True, help="Random seed of the scene and of the faults."
)
@option(
    "--duration",
    bound=OPTIONS["sim_duration"],
    default=None,
    help="Seconds of scene to simulate before it repeats [default: the scene's].",
)
@click.option(
    "--baud",
    type=click.Choice(["9600", "19200", "38400", "500000"]),
    default="9600",
    show_default=True,
    help="Baud at power-up (a real LMS200 starts at 9600).",
)
@click.option(
    "--angle",
    type=click.Choice(["180", "100"]),
    default="180",
    show_default=True,
    help="Field of view at power-up, degrees.",
)
@click.option(
    "--resolution",
    type=click.Choice(["1", "0.5", "0.25"]),
    default="0.5",
    show_default=True,
    help="Resolution at power-up, degrees.",
)
@click.option("--units", type=click.Choice(["mm", "cm"]), default="mm", show_default=True, help="Units at power-up.")
@click.option("--indices", is_flag=True, help="Send real-time scan indices from power-up.")
@click.option("--fault", "fault_spec", default=None, metavar="SPEC", help=FAULT_HELP)
@click.option(
    "--link",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also make a symlink at this path to the pseudo-terminal (removed on exit). An existing path is "
    "refused unless --force, which replaces only a symlink or a regular file.",
)
@force_option("Let --link replace an existing symlink or regular file.")
@quiet_option
def command(
    scene: str | None,
    log_path: Path | None,
    seed: int,
    duration: float | None,
    baud: str,
    angle: str,
    resolution: str,
    units: str,
    indices: bool,
    fault_spec: str | None,
    link: Path | None,
    force: bool,
) -> None:
    """Run a virtual SICK LMS200 on a pseudo-terminal until Ctrl-C (exit 130; SIGTERM 143, SIGHUP 129).

    Prints the device path to give `datmo record --port`. The device follows the LMS2xx serial protocol
    (power-up at 9600 Bd, baud changes, variant and configuration commands, NAK on bad CRCs, continuous
    and interlaced output at the real scan period, whole scans dropped below 500 kBd as the rate table
    says). Bytes are paced in software at baud/10 bytes per second; a host set to the wrong baud gets
    garbage. Scans come from a simulated scene or a log.

    Example: datmo emulate --scene hall --fault garbage:0.05,crc:0.01
    """
    from ..base.errors import ConfigError
    from ..base.progress import quiet
    from ..lms2xx.emulator import Emulator
    from ..lms2xx.faults import Faults
    from ..passes.simulated import scan_source

    silent = quiet()  # read here: the emulator's thread, which also says things, has no Click context

    def say(text: str) -> None:
        if not silent:
            click.echo(text, err=True)

    if log_path is not None and scene is not None:
        raise ConfigError("give --scene or --log, not both")
    if angle == "180" and resolution == "0.25":
        raise click.BadParameter("0.25° is available only with --angle 100", param_hint="--resolution")
    if link is not None:
        from ..base.outputs import check_output

        check_output(link, force=force, what="link")  # before the device starts
    faults = Faults.parse(fault_spec)
    source = scan_source(log=log_path, scene=scene, seed=seed, duration=duration)
    emu = Emulator(
        source,
        faults=faults,
        seed=seed,
        baud=int(baud),
        angle_deg=int(angle),
        resolution_deg=float(resolution),
        units=units,
        indices=indices,
        on_event=lambda text: say(f"emulate: {text}"),
    )
    done = threading.Event()
    stopped_by: list[int] = []

    def handler(signum, frame) -> None:
        stopped_by.append(signum)
        done.set()

    old = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    emu.start()
    made = None
    try:
        if link is not None:
            made = make_link(emu.device_path, link, force)
        click.echo(emu.device_path)
        what = f"log {log_path}" if log_path is not None else f"scene {scene or 'hall'}"
        say(f"emulate: LMS200 on {emu.device_path} at {baud} Bd serving {what}; Ctrl-C to stop")
        while not done.wait(0.2):
            if emu.disconnected.is_set():
                click.echo("emulate: disconnected (fault)", err=True)
                break
    finally:
        emu.stop()
        if made is not None and link is not None:
            remove_link(link, made)
        for sig, h in old.items():
            signal.signal(sig, h)
    try:
        say(f"emulate: sent {len(emu.sent)} scans; faults {dict(emu.stats.faults) or 'none'}")
    except OSError:  # the terminal hung up (SIGHUP)
        pass
    if stopped_by:  # stopping is how an emulator ends, but the status says how: 130, 143 or 129
        raise click.exceptions.Exit(128 + stopped_by[0])


def make_link(target: str, link: Path, force: bool) -> tuple[int, int]:
    """Make `link` a symlink to `target` (a symlink made beside it, renamed over it, so an existing symlink or
    regular file is replaced only when outputs.check_output allows it); returns the link's (device, inode)."""
    from ..base import outputs

    outputs.check_output(link, force=force, what="link")
    with outputs.critical():
        tmp = outputs.temp_path(link)
        try:
            os.symlink(target, tmp)
            outputs.track(tmp)
        except OSError as exc:
            raise outputs.os_error(exc, link, "making the link") from None
    outputs.commit(tmp, link, force)
    st = os.lstat(link)
    return st.st_dev, st.st_ino


def remove_link(link: Path, made: tuple[int, int]) -> None:
    """Remove `link` if it is still the symlink make_link made (not a file put there since)."""
    try:
        st = os.lstat(link)
        if (st.st_dev, st.st_ino) == made and os.path.islink(link):
            os.unlink(link)
    except OSError:
        pass
