"""`datmo emulate`: a virtual LMS200 on a pseudo-terminal, to test `datmo record` without hardware: the options, the
signals, one call of datmo_cli.api.emulate (workflows.emulating) and what it says."""

from __future__ import annotations

import signal
import threading
from pathlib import Path

import click

from ..base.bounds import OPTIONS
from ..workflows.emulating import make_link, remove_link  # noqa: F401  (their home was here)
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
    from .. import api
    from ..base.errors import ConfigError
    from ..base.progress import quiet

    silent = quiet()  # read here: the emulator's thread, which also says things, has no Click context

    def say(text: str) -> None:
        if not silent:
            click.echo(text, err=True)

    if log_path is not None and scene is not None:
        raise ConfigError("give --scene or --log, not both")
    if angle == "180" and resolution == "0.25":
        raise click.BadParameter("0.25° is available only with --angle 100", param_hint="--resolution")
    emulation = api.emulate(
        scene,
        log_path,
        seed=seed,
        duration=duration,
        baud=baud,
        angle=angle,
        resolution=resolution,
        units=units,
        indices=indices,
        faults=fault_spec,
        link=link,
        force=force,
        on_event=lambda text: say(f"emulate: {text}"),
    )
    done = threading.Event()
    stopped_by: list[int] = []

    def handler(signum, frame) -> None:
        stopped_by.append(signum)
        done.set()

    old = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    try:
        with emulation:
            click.echo(emulation.device_path)
            say(f"emulate: LMS200 on {emulation.device_path} at {baud} Bd serving {emulation.serving}; Ctrl-C to stop")
            if not emulation.serve(done):
                click.echo("emulate: disconnected (fault)", err=True)
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)
    try:
        say(f"emulate: {emulation.report}")
    except OSError:  # the terminal hung up (SIGHUP)
        pass
    if stopped_by:  # stopping is how an emulator ends, but the status says how: 130, 143 or 129
        raise click.exceptions.Exit(128 + stopped_by[0])
