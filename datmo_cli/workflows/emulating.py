"""`datmo emulate`'s work as a call (datmo_cli.api.emulate): a virtual SICK LMS200 (lms2xx.emulator) on a
pseudo-terminal serving the scans of a simulated scene or of a log (ranges in the variant's units, beams mapped
by angle), with injected faults, and an optional symlink to its device. The command keeps the terminal's part:
the signals that stop it, the device path it prints and what it says."""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from pathlib import Path


class Emulation:
    """A virtual LMS200 ready to start: its scan source read and its faults parsed; `start()` (or `with`) opens
    the pseudo-terminal (`device_path`, the port to give `datmo record` or api.record) and makes the `link`;
    `serve(stop)` waits until `stop` is set or a fault hangs up; `stop()` (or the end of the `with`) closes the
    device and removes the link it made.

    `scene` (a built-in name or a .toml; default hall) or `log` (an MCAP log, repeated); `seed` of the scene and
    of the faults; `duration` s of scene before it repeats; the power-up state: `baud` (9600, 19200, 38400,
    500000), `angle` (180 or 100 degrees), `resolution` (1, 0.5, 0.25 degrees; 0.25 with angle 100 only),
    `units` ("mm" or "cm"), `indices`; `faults` as `datmo emulate --fault` takes them (e.g.
    "garbage:0.1,crc:0.05,disconnect:500"); `link`: also a symlink to the device there (an existing path
    refused unless `force`); `on_event(text)` hears what the device does (from its own thread)."""

    def __init__(
        self,
        scene: str | None = None,
        log: str | os.PathLike | None = None,
        *,
        seed: int = 0,
        duration: float | None = None,
        baud: int | str = 9600,
        angle: int | str = 180,
        resolution: float | str = 0.5,
        units: str = "mm",
        indices: bool = False,
        faults: str | None = None,
        link: str | os.PathLike | None = None,
        force: bool = False,
        on_event: Callable[[str], None] | None = None,
    ) -> None:
        from ..base.errors import ConfigError
        from ..lms2xx.emulator import Emulator
        from ..lms2xx.faults import Faults
        from ..passes.simulated import scan_source

        if log is not None and scene is not None:
            raise ConfigError("give --scene or --log, not both")
        if int(angle) == 180 and float(resolution) == 0.25:
            raise ConfigError("0.25° is available only with angle 100")
        self.link = Path(link) if link is not None else None
        self.force = force
        if self.link is not None:
            from ..base.outputs import check_output

            check_output(self.link, force=force, what="link")  # before the device starts
        self.log, self.scene, self.baud = log, scene, int(baud)
        parsed = Faults.parse(faults)
        source = scan_source(log=Path(log) if log is not None else None, scene=scene, seed=seed, duration=duration)
        self.emulator = Emulator(
            source,
            faults=parsed,
            seed=seed,
            baud=int(baud),
            angle_deg=int(angle),
            resolution_deg=float(resolution),
            units=units,
            indices=indices,
            on_event=on_event,
        )
        self._made: tuple[int, int] | None = None

    @property
    def device_path(self) -> str:
        """The pseudo-terminal's path ("" until started)."""
        return self.emulator.device_path

    @property
    def serving(self) -> str:
        """What it serves: "log PATH" or "scene NAME"."""
        return f"log {self.log}" if self.log is not None else f"scene {self.scene or 'hall'}"

    @property
    def disconnected(self) -> threading.Event:
        """Set when a disconnect fault hung up."""
        return self.emulator.disconnected

    def start(self) -> Emulation:
        """Open the device and start serving; make the link (the device stopped again if that fails)."""
        self.emulator.start()
        if self.link is not None:
            try:
                self._made = make_link(self.emulator.device_path, self.link, self.force)
            except BaseException:
                self.emulator.stop()
                raise
        return self

    def serve(self, stop: threading.Event, poll_s: float = 0.2) -> bool:
        """Serve until `stop` is set (True) or a disconnect fault hangs up (False); checked every `poll_s` s."""
        while not stop.wait(poll_s):
            if self.emulator.disconnected.is_set():
                return False
        return True

    def stop(self) -> None:
        """Close the device; remove the link if it is still the one made."""
        self.emulator.stop()
        made, self._made = self._made, None
        if made is not None and self.link is not None:
            remove_link(self.link, made)

    @property
    def report(self) -> str:
        """What was sent: the scans and the faults injected."""
        return f"sent {len(self.emulator.sent)} scans; faults {dict(self.emulator.stats.faults) or 'none'}"

    def __enter__(self) -> Emulation:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def emulate(scene: str | None = None, log: str | os.PathLike | None = None, **options) -> Emulation:
    """`datmo emulate`: an Emulation of `scene` or `log` with `options` (Emulation's), not yet started: use it
    as a context manager (`with api.emulate("hall") as lms: api.record(lms.device_path, ...)`)."""
    return Emulation(scene, log, **options)


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
